"""sim2radar.detect"""
