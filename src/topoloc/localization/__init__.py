"""Temporally consistent localization: hypothesis decoding of RNN outputs, an HMM baseline, evaluation, plots."""
