"""holoslam.graph"""
