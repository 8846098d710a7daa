"""Estimators of the target position from synchronized observations (paper sections 2.1-2.4, plus MLE)."""
