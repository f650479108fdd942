"""sim2radar.em"""
