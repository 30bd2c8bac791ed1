"""Replay of real flight logs: a data source other than simulation (docs/replay.md).

:mod:`quadest.replay.ulog` reads a PX4 ULog file, :mod:`quadest.replay.align` puts its samples on
the filter's time grid and :mod:`quadest.replay.data` fills the Monte Carlo data from them; the
replay job's outputs are made by :mod:`quadest.app.replay_job`. There is no truth in a real
log: the filters are compared with PX4's own onboard estimate, and the outputs call that the
*difference to PX4*. A simulation (SITL) log's ground truth, where present, scores the filters and
PX4's estimate alike; :mod:`quadest.replay.declination` turns our magnetic yaw to PX4's true north.
"""
