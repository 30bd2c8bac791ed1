"""Sensors on the quadrotor: the MIMU (accelerometer and gyro triads with the chapter-5 error
classes) and the rotor encoders that give the filters their input; and the further sensors a
model updates with at their own rates (:mod:`quadest.sensors.base`, one class each: GPS,
barometer, camera, magnetometer, and any plugin's, found by :mod:`quadest.sensors.registry`)."""
