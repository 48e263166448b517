"""holoslam.submaps: local geometric maps and the SLAM front end (seed 002 Eq. 10-16), numpy/OpenCV only.

deadreckon (Eq. 14-15 with analytic covariance), features (scan features H), localize (Eq. 12: pairs, RANSAC,
point-to-line ICP), segment (submap policy, Submap record, local grid), frontend (build_problem -> FrontEnd).
"""
