"""holoslam.planning"""
