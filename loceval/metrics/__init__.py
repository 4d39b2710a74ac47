"""Error metrics of an aligned estimate.

ATE, RPE, drift, the greatest errors and the share within thresholds (:mod:`.pose_errors`);
deviations between re-driven paths (:mod:`.repeatability`).
"""
