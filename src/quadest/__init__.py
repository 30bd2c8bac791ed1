"""quadest: comparing nonlinear state estimators on a micro-quadrotor.

The centre is the square-root UKF of a quadrotor thesis (chapter 5, eqs 5.1–5.29), run beside
filterpy's EKF and UKF on one shared quadrotor model with a MIMU.
"""

__version__ = "0.1.0"
