"""The source paper's published figures, recorded once.

Ni, Liu, Wu, Wu, "Time-varying state-space model identification of an
on-orbit rigid-flexible coupling spacecraft using an improved
predictor-based recursive subspace algorithm", Acta Astronautica 163 (2019)
157-167. Keys of the method tables are this package's method names
(:data:`spacecraft_lab.identification.METHODS`).
"""

from __future__ import annotations

__all__ = ["PAPER_METHOD_NAMES", "PAPER_SNR_DB", "PAPER_TABLE5", "PAPER_TABLES"]

#: The paper's measurement SNR, dB per channel, relative to each channel's RMS over
#: the record (its identification experiments; :func:`identifiers.add_measurement_noise`).
PAPER_SNR_DB = 40.0

#: Our method name -> the paper's name for it.
PAPER_METHOD_NAMES: dict[str, str] = {"improved-rpbsid": "improved RPBSID",
                                      "classical-rpbsid": "classical RPBSID",
                                      "windowed-pbsid": "SVD-based"}

#: Average relative test-response errors (%), Tables 3 (docking, attitude
#: only) and 4 (solar rotation); keys: scenario, our method name, group.
PAPER_TABLES: dict[str, dict[str, dict[str, list[float]]]] = {
    "docking": {
        "classical-rpbsid": {"psi": [3.0835, 2.3342, 2.7766]},
        "windowed-pbsid": {"psi": [2.6808, 2.4893, 3.6031]},
        "improved-rpbsid": {"psi": [3.4380, 3.2092, 2.9923]},
    },
    "solar_rotation": {
        "classical-rpbsid": {"psi": [3.4729, 1.6783, 2.9235], "omega": [5.8796, 6.6838, 7.4765]},
        "windowed-pbsid": {"psi": [1.9646, 1.2601, 2.6480], "omega": [5.0194, 6.8414, 8.6877]},
        "improved-rpbsid": {"psi": [2.9664, 1.6217, 3.5811], "omega": [5.7382, 8.9119, 7.7325]},
    },
}

#: Table 5: average MATLAB computation time (s) per run over 30 Monte-Carlo
#: runs, by system order n; keys: our method names.
PAPER_TABLE5: dict[str, dict[int, float]] = {
    "classical-rpbsid": {22: 14.64, 30: 23.35, 38: 34.23, 46: 46.96},
    "improved-rpbsid": {22: 12.27, 30: 19.56, 38: 28.99, 46: 39.22},
    "windowed-pbsid": {22: 26.15, 30: 37.01, 38: 50.51, 46: 68.10},
}
