"""holoslam.sim"""
