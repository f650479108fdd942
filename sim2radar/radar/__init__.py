"""sim2radar.radar"""
