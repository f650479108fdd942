"""sim2radar.datasets"""
