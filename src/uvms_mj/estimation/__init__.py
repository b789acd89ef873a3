"""State estimation (issue 21): the measurements the navigation sensors give and the estimator takes
(measurements.py), the error-state Kalman filter (eskf.py) and its measurement models (models.py)."""

from uvms_mj.estimation.eskf import ESKF, EskfParams, NavEstimate, NavState
from uvms_mj.estimation.measurements import DepthSample, DvlSample, FixSample, ImuSample, Mount
from uvms_mj.estimation.models import EstimatorError

__all__ = ["DepthSample", "DvlSample", "ESKF", "EskfParams", "EstimatorError", "FixSample", "ImuSample", "Mount",
           "NavEstimate", "NavState"]
