"""Example quadest plugin: an iterated extended Kalman filter."""
