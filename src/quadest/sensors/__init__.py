"""Sensors on the quadrotor: the MIMU (accelerometer and gyro triads with the chapter-5 error
classes) and the rotor encoders that give the filters their input."""
