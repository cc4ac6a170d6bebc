"""Reference numbers from the C-DNF paper (its Tables I and II; docs/EVALUATION.md)."""
from __future__ import annotations

#: Table I: 1 = the model alerts on the stimulus. Keys are cdnf_ti model names.
TABLE1: dict[str, dict[str, int]] = {
    "cdnf": {"dark_looming": 1, "light_looming": 1, "dark_receding": 1, "light_receding": 1,
             "dark_translating": 0, "light_translating": 0},
    "sdnf": {"dark_looming": 1, "light_looming": 1, "dark_receding": 0, "light_receding": 0,
             "dark_translating": 1, "light_translating": 1},
    "lgmd2": {"dark_looming": 1, "light_looming": 0, "dark_receding": 0, "light_receding": 0,
              "dark_translating": 0, "light_translating": 0},
    "flgmd_onn": {"dark_looming": 1, "light_looming": 1, "dark_receding": 1, "light_receding": 1,
                  "dark_translating": 0, "light_translating": 0},
}

#: Table II: accuracy (%) on the paper's 35 real clips, clean and with synthetic rain.
TABLE2: dict[str, dict[str, float]] = {
    "cdnf": {"clean": 77.14, "rain": 77.14},
    "sdnf": {"clean": 22.86, "rain": 20.0},
    "lgmd2": {"clean": 34.29, "rain": 40.0},
    "flgmd_onn": {"clean": 28.57, "rain": 0.0},
}

#: Dataset-average SNR of the paper's synthetic rain (dB).
RAIN_SNR_DB = 19.7
