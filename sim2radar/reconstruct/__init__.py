"""sim2radar.reconstruct"""
