"""Estimators of one model at a time: the papers' observers (reduced-order, LMI functional), the
augmented-state EKF, the steady-state Kalman filter with a track shaping filter and the RTS
smoother.  They take matrices, never vehicles; the batched machinery is :mod:`railpaper.engine`."""
