"""holoslam.submaps"""
