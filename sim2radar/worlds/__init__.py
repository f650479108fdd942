"""sim2radar.worlds"""
