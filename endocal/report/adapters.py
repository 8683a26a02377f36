"""Where the report takes its numbers from offline validation, in one place.

The report renders what ``endocal validate`` computes and never recomputes it another way:
the axis data a model sees (:func:`endocal.validation.data.axis_data`), the prediction with
the model continued beyond its fitted range and those samples counted (as ``validate_offline``
does), the
error metrics (:func:`endocal.validation.metrics.error_metrics`), the error by regime
(:func:`endocal.validation.regimes.error_by_regime`) and the command's direction reversals
(:func:`endocal.validation.regimes.turning_points`).
"""

from __future__ import annotations

from endocal.validation.data import axis_data
from endocal.validation.offline import predict_extrapolated
from endocal.validation.regimes import Regime, RegimeBreakdown, error_by_regime, turning_points

__all__ = ["Regime", "RegimeBreakdown", "axis_data", "error_by_regime", "predict_extrapolated", "turning_points"]
