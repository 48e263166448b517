"""holoslam.maps"""
