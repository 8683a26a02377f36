"""Holding a model against measurements: error metrics, where the model fails, what is missing."""

from endocal.validation.metrics import METRIC_KEYS, ErrorMetrics, error_metrics

__all__ = ["METRIC_KEYS", "ErrorMetrics", "error_metrics"]
