"""Residual analysis: is the model's error noise, and if not, what is its structure?

Pure functions of arrays (numpy/scipy, vectorised), independent of the robot and of the measured
quantity: a *channel* is any measured signal the model predicts (the base angular rate
``omega_base_body`` wx, wy, wz in rad/s for the free-floating robot; joint torques in N m for a
fixed-base arm), so every function takes C channels. Time ``t_s`` is in s; joint angles ``q`` in
rad, rates ``dq`` in rad/s (revolute joints), ``T`` samples, ``n`` joints.

The standard tests that tell a structured error from noise (Ljung, *System Identification*, 2nd
ed. 1999, sec. 16.6; Box, Jenkins & Reinsel, *Time Series Analysis*, ch. 8 and 11):

* :func:`fit_percent`: ``100 (1 - |y - yhat| / |y - mean y|)`` per channel (2-norms), the "fit"
  figure system-identification tools report;
* :func:`noise_floor_std`: a data-only estimate of the white-noise standard deviation that ignores
  smooth structure (median absolute deviation of differences);
* :func:`autocorrelation` with the band :func:`white_noise_band` and the portmanteau test
  :func:`ljung_box` (whiteness);
* :func:`cross_correlation` with the inputs (joint rates and accelerations) and a per-input test;
* :func:`dominant_frequencies`: significant spectral lines of the residual;
* :func:`failing_segments`: the time windows where the residual exceeds the noise, with what the
  arm was doing there;
* :func:`analyse_residuals`: all of it in one :class:`ResidualAnalysis` (inputs band-limited by :func:`band_limited_inputs`).

Multiple testing: every "significant" below is at ``alpha = 1 - confidence`` *family-wise*
(Bonferroni or Holm over the lags, windows, inputs and channels that make up one question), so a
residual of pure noise is declared structured with probability at most ``alpha``.

The modules: :mod:`.noise` (fit percent, noise floor), :mod:`.correlation` (autocorrelation, Ljung-Box,
cross-correlation with the inputs), :mod:`.spectrum` (periodogram, spectral lines), :mod:`.segments` (failing time
windows), :mod:`.analysis` (:func:`analyse_residuals`, :class:`ResidualAnalysis`); every name is importable from
this package.
"""

from __future__ import annotations

from estimators.diagnostics.residuals.analysis import ResidualAnalysis as ResidualAnalysis
from estimators.diagnostics.residuals.analysis import analyse_residuals as analyse_residuals
from estimators.diagnostics.residuals.analysis import band_limited_inputs as band_limited_inputs
from estimators.diagnostics.residuals.correlation import CrossCorrelation as CrossCorrelation
from estimators.diagnostics.residuals.correlation import autocorrelation as autocorrelation
from estimators.diagnostics.residuals.correlation import cross_correlation as cross_correlation
from estimators.diagnostics.residuals.correlation import ljung_box as ljung_box
from estimators.diagnostics.residuals.correlation import white_noise_band as white_noise_band
from estimators.diagnostics.residuals.noise import fit_percent as fit_percent
from estimators.diagnostics.residuals.noise import noise_floor_dof as noise_floor_dof
from estimators.diagnostics.residuals.noise import noise_floor_std as noise_floor_std
from estimators.diagnostics.residuals.segments import MOVING_THRESHOLD_RAD_S as MOVING_THRESHOLD_RAD_S
from estimators.diagnostics.residuals.segments import Segment as Segment
from estimators.diagnostics.residuals.segments import failing_segments as failing_segments
from estimators.diagnostics.residuals.spectrum import SpectralPeak as SpectralPeak
from estimators.diagnostics.residuals.spectrum import dominant_frequencies as dominant_frequencies
from estimators.diagnostics.residuals.spectrum import periodogram as periodogram
from estimators.diagnostics.residuals.spectrum import white_spectrum_level as white_spectrum_level
