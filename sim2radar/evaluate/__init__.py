"""sim2radar.evaluate"""
