"""dtwin: find, explain and mitigate error in modular digital twins.

Reproduces "Hidden Markov Inference Framework for Error Propagation Mitigation in Modular
Digital Twins" (six-module twin, ARX surrogates, residual regimes) as a library and a
Snakemake workflow.

Conventions: arrays are time-first everywhere, shape ``(T,)`` or ``(T, n_channels)``; signals
keep the paper's names (``u_cmd, u_act, x, v, y_A, y_B, y_fused, z``) and residuals are
``e0, e1, e2a, e2b, e3, e4`` (surrogate − physics). Errors are :class:`DtwinValueError` /
:class:`DtwinTypeError`, subclasses of the builtin ``ValueError`` / ``TypeError``.

Public names are re-exported lazily (PEP 562), so ``import dtwin`` stays cheap and a script
pays only for the modules it uses.
"""

from __future__ import annotations

from dtwin._lazy import lazy_exports

__version__ = "0.1.0"

_EXPORTS: dict[str, str] = {
    # errors
    "DtwinValueError": "dtwin._validation",
    "DtwinTypeError": "dtwin._validation",
    # wiring and parameters (paper §3)
    "MODULES": "dtwin.twin.wiring",
    "SIGNALS": "dtwin.twin.wiring",
    "RESIDUALS": "dtwin.twin.wiring",
    "Module": "dtwin.twin.wiring",
    "TwinParams": "dtwin.params",
    "CommandParams": "dtwin.params",
    "twin_params_from_mapping": "dtwin.params",
    "command_params_from_mapping": "dtwin.params",
    # physics (paper §3.1)
    "make_command": "dtwin.command",
    "actuator_lpf": "dtwin.physics",
    "plant_msd": "dtwin.physics",
    "sensor_first_order": "dtwin.physics",
    "fuse": "dtwin.physics",
    "kpi": "dtwin.physics",
    "backward_velocity": "dtwin.physics",
    "simulate_physics": "dtwin.physics",
    # surrogates and residuals (paper §3.2, Eq. (1))
    "ArxOrders": "dtwin.arx",
    "ArxFit": "dtwin.arx",
    "fit_arx": "dtwin.arx",
    "simulate_arx": "dtwin.arx",
    "fit_surrogates": "dtwin.surrogate",
    "run_surrogate_chain": "dtwin.surrogate",
    "compute_residuals": "dtwin.surrogate",
    # structured residuals (paper §4.1)
    "acf_table": "dtwin.residual_stats",
    "ljung_box_table": "dtwin.residual_stats",
    # regimes: Gaussian HMM (paper §2.1, §4.2)
    "zscore": "dtwin.hmm",
    "fit_hmm": "dtwin.hmm",
    "HmmFit": "dtwin.hmm",
    "filtered_posteriors": "dtwin.hmm",
    "bic_by_k": "dtwin.hmm",
    # bias correction (paper §4.3, Eq. (25))
    "correct_bias": "dtwin.bias_correction",
    # fault injection and regime scoring (paper §4.4)
    "inject_faults": "dtwin.fault_injection",
    "regime_features": "dtwin.fault_injection",
    "hungarian_map": "dtwin.regime_matching",
    "classification_scores": "dtwin.regime_matching",
    # decisions (paper §5, Table 1)
    "topsis": "dtwin.mcda",
    "run_mcda": "dtwin.mcda",
    # sim-to-real gap diagnosis
    "diagnose": "dtwin.gap",
    "read_recording": "dtwin.gap",
    "generate_case": "dtwin.gapbench",
    # sensitivity sweep (paper §5, Fig. 11)
    "SweepPoint": "dtwin.sensitivity_sweep",
    "SweepRun": "dtwin.sensitivity_sweep",
    "sweep_grid": "dtwin.sensitivity_sweep",
    "replicate_seed": "dtwin.sensitivity_sweep",
    "sweep_table": "dtwin.sensitivity_sweep",
    "summarize_sweep": "dtwin.sensitivity_sweep",
    "sweep_point": "dtwin.stages.sensitivity",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
