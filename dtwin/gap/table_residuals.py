"""Module residuals of a recording against a twin table: the paper's method on a user's twin.

Specification: docs/gap.md §Twin file (Residuals). Each unit of the table
(:func:`dtwin.twin.simulate.units_of`) is fitted on the training part as the diagnoser fits it
(:mod:`dtwin.gap.table_diagnose`: params within the calibration tolerance, or freely with
``calibrate``), then simulated over windows that tile the whole recording, each window's
initial states fitted; the residual of each recorded output is ``recorded − twin``. These are
the residual channels over which the paper's HMM (Sec. 3.3) finds regimes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from threadpoolctl import threadpool_limits

from dtwin.gap.recording import Recording
from dtwin.gap.results import GapSettings
from dtwin.gap.table_diagnose import _analyse_unit, _split
from dtwin.gap.table_fit import UnitData, VariantFit, part_error
from dtwin.twin.simulate import units_of

__all__ = ["TableResiduals", "table_residuals"]


@dataclass(frozen=True)
class TableResiduals:
    """Residual channels of a recording against a twin table.

    Attributes
    ----------
    t : numpy.ndarray, shape (n_samples,)
        Time, s (the recording's).
    residuals : pandas.DataFrame, shape (n_samples, n_channels)
        ``recorded − twin`` per recorded output, columns ``<unit>:<signal>`` (``unit`` its
        modules joined by ``+``), in the recording's units.
    simulated : pandas.DataFrame, shape (n_samples, n_channels)
        The twin's outputs, same columns.
    params : dict of str to dict of str to float
        Each unit's fitted params (qualified names).
    window : dict of str to int
        Each unit's window, samples.
    """

    t: np.ndarray
    residuals: pd.DataFrame
    simulated: pd.DataFrame
    params: dict[str, dict[str, float]]
    window: dict[str, int]
    units: dict[str, UnitData] = field(default_factory=dict, repr=False)
    fits: dict[str, VariantFit] = field(default_factory=dict, repr=False)


def table_residuals(
    recording: Recording,
    table,
    *,
    calibrate: bool = False,
    train_frac: float = 0.5,
    settings: GapSettings | None = None,
) -> TableResiduals:
    """Return every recorded output's residual against the twin table, over the whole recording.

    Parameters
    ----------
    recording : Recording
        With every signal the table reads from the recording.
    table : dtwin.twin.table.TwinTable
    calibrate : bool
        Fit every param freely on the training part.
    train_frac : float
        Share of the samples, from the start, the twin is fitted on.
    settings : GapSettings, optional

    Returns
    -------
    TableResiduals
    """
    settings = settings or GapSettings()
    parts = _split(recording.n_samples, train_frac, settings.choose_frac)
    residuals, simulated, params, windows, units, fits = {}, {}, {}, {}, {}, {}
    with threadpool_limits(limits=1):
        for spec in units_of(table, list(recording.signals)):
            work = _analyse_unit(spec, recording, table, parts, settings, calibrate)
            error = np.full_like(work.data.outputs, np.nan)
            model = np.full_like(work.data.outputs, np.nan)
            for part, (start, stop) in parts.items():
                e, y = part_error(work.data, work.nominal, part, cap=None)
                error[start:stop], model[start:stop] = e[start:stop], y[start:stop]
            for o, signal in enumerate(spec.outputs):
                residuals[f"{spec.name}:{signal}"] = -error[:, o]
                simulated[f"{spec.name}:{signal}"] = model[:, o]
            params[spec.name] = {k: float(v) for k, v in work.nominal.theta.items()}
            windows[spec.name] = work.data.window
            units[spec.name], fits[spec.name] = work.data, work.nominal
    return TableResiduals(
        recording.t, pd.DataFrame(residuals), pd.DataFrame(simulated), params, windows, units, fits
    )
