"""The estimator in the control loop (seed 003).

- :mod:`~quadest.closed_loop.feedback`: what the controller reads (truth, noisy states, an estimate);
- :mod:`~quadest.closed_loop.loop`: the plant flown under a controller and a feedback source;
- :mod:`~quadest.closed_loop.control_metrics`: tracking, step-response and effort metrics;
- :mod:`~quadest.closed_loop.quadrotor`: the quadrotor's closed-loop set-up;
- :mod:`~quadest.closed_loop.seed003`: seed 003's arms (EKF in / EKF out) with its 5-state filter;
- :mod:`~quadest.closed_loop.loops`: which model each closed loop flies (the loop of a job);
- :mod:`~quadest.closed_loop.seed003_report`: seed 003's paired table;
- :mod:`~quadest.closed_loop.control_tables`: a job's control tables and their ``summary.json`` entry;
- :mod:`~quadest.closed_loop.report`: the loop modes of a sweep side by side (after a sweep, by the
  callback :class:`quadest.app.callbacks.ClosedLoopReport`).

A job with ``loop`` other than ``open`` is the closed-loop kind of the one job pipeline
(:mod:`quadest.app.closed_loop_job`). Its settings (the ``loop`` key, the state sensor and the
crash limits) are :mod:`quadest.config.closed_loop`, which the models read too. See
``docs/closed-loop.md``.
"""
