"""Figures are written, non-empty, and show what they claim (window shading, alerts, model rows)."""
from __future__ import annotations

import numpy as np
import pytest

from cdnf_ti.experiments.labels import ClipLabel
from cdnf_ti.experiments.scoring import Padding
from cdnf_ti.models.base import Trace


def _img(path):
    import matplotlib.image as mpimg

    assert path.is_file() and path.stat().st_size > 5_000
    return mpimg.imread(str(path))[..., :3]


def _has_colour(img, rgb, tol=0.06) -> int:
    return int((np.abs(img - np.asarray(rgb)).max(axis=2) < tol).sum())


def _pinkish(img) -> int:
    """Pixels of the window shading's hue (pink: red high, green lowest, blue between)."""
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return int(((r > 0.9) & (r - g > 0.08) & (b - g > 0.03) & (r - b > 0.05)).sum())


def _trace(n=60, jump=45, thr=0.506) -> Trace:
    out = np.full(n, 0.5)
    out[jump:] = np.linspace(0.505, 0.54, n - jump)
    return Trace("cdnf", "I_v", thr, out, out > thr, np.ones(n, bool), {})


def test_clip_figure_shades_the_window_and_draws_each_model(tmp_path):
    from cdnf_ti.experiments.figures import plot_clip

    lab = ClipLabel("c", "collision", True, 40, 50, 48, 2)
    traces = {("cdnf", "clean"): _trace(), ("cdnf", "rain"): _trace(jump=42), ("other", "clean"): _trace()}
    one = plot_clip(tmp_path / "one.png", lab, traces, ["cdnf"], ["clean", "rain"], 30.0, Padding(3, 3))
    two = plot_clip(tmp_path / "two.png", lab, traces, ["cdnf", "other"], ["clean", "rain"], 30.0)
    img1, img2 = _img(one), _img(two)
    assert _pinkish(img1) > 5000
    assert img2.shape[0] > 1.5 * img1.shape[0]  # a row per model
    assert _has_colour(img1, (0.12, 0.47, 0.71), 0.08) > 50  # the clean trace (tab:blue)


def test_non_collision_clip_figure_has_no_window(tmp_path):
    from cdnf_ti.experiments.figures import plot_clip

    lab = ClipLabel("n", "non-collision", False, None, None, None, 2)
    img = _img(plot_clip(tmp_path / "n.png", lab, {("cdnf", "clean"): _trace()}, ["cdnf"], ["clean"]))
    assert _pinkish(img) < 50


def test_threshold_sweep_and_accuracy_figures(tmp_path):
    from cdnf_ti.experiments.figures import plot_accuracy, plot_threshold_sweep
    from cdnf_ti.experiments.sweep import SweepSpec

    spec = SweepSpec("cdnf", "epsilon", (0.0, 0.01, 0.02), 0.01, "cdnf-epsilon")
    rows = [dict(model="cdnf", condition=c, value=v, accuracy=a, hits=h, false_alarms=f, is_default=v == 0.01)
            for c in ("clean", "rain") for v, a, h, f in ((0.0, 0.2, 3, 4), (0.01, 0.8, 3, 0), (0.02, 0.5, 1, 0))]
    _img(plot_threshold_sweep(tmp_path / "s.png", rows, {"cdnf": spec}))
    res = {"cdnf": {"clean": {"accuracy": 0.8}, "rain": {"accuracy": 0.6}}}
    img = _img(plot_accuracy(tmp_path / "a.png", res, ["cdnf"], ["clean", "rain"]))
    assert _has_colour(img, (1.0, 0.50, 0.05), 0.08) > 200  # the rain bar (tab:orange)


def test_selectivity_panel_from_table1(tmp_path):
    from cdnf_ti.experiments.builtin import table1

    res = table1(["cdnf"], tmp_path, size=64, workers=0, progress=False)
    assert set(res["cdnf"]) == {"dark_looming", "light_looming", "dark_receding", "light_receding",
                                "dark_translating", "light_translating"}
    img = _img(tmp_path / "figures" / "basic_selectivity.png")
    assert img.shape[1] > 1000
    assert (tmp_path / "table1.md").read_text().count("|") > 20


def test_coherence_panel_from_the_sweep(tmp_path):
    pytest.importorskip("cdnf_ti.stimuli.incoherent")
    from cdnf_ti.experiments.builtin import coherence_sweep
    from cdnf_ti.experiments.figures import MODEL_COLOURS

    table = coherence_sweep(["cdnf"], tmp_path, size=64, coherences=(1.0, 0.2), workers=0, progress=False,
                            stimuli=["dark_looming", "dark_translating"])
    assert set(table) == {"dark_looming", "dark_translating"}
    assert set(table["dark_looming"]["cdnf"]) == {1.0, 0.2}
    img = _img(tmp_path / "figures" / "coherence_sweep.png")
    n_alerts = sum(r["alert"] for d in table.values() for r in d["cdnf"].values())
    from matplotlib.colors import to_rgb

    red = _has_colour(img, to_rgb(MODEL_COLOURS[0]), 0.05)
    assert (red > 100) == (n_alerts > 0)
    md = (tmp_path / "coherence.md").read_text()
    assert "| Dark approaching | cdnf |" in md and "20%" in md


def test_accuracy_value_labels_sit_clear_of_the_papers_diamonds(tmp_path, monkeypatch):
    """Each bar's value label starts above its bar and above the paper's diamond at that bar, whichever is
    higher (the C-DNF bars match the paper, so a label just above the bar sat under the diamond)."""
    from cdnf_ti.experiments import figures
    from cdnf_ti.paper import TABLE2

    figs = []
    monkeypatch.setattr(figures, "save_figure", lambda fig, path, dpi=110: figs.append(fig) or path)
    models = list(TABLE2)
    res = {m: {c: {"accuracy": TABLE2[m][c] / 100} for c in ("clean", "rain")} for m in models}  # bars = paper
    figures.plot_accuracy(tmp_path / "a.png", res, models, ["clean", "rain"])
    ax = figs[0].axes[0]
    diamonds = [(x, y) for line in ax.lines if line.get_marker() == "D" for x, y in zip(*line.get_data())]
    labels = [t for t in ax.texts if t.get_text().isdigit()]
    assert len(labels) == len(diamonds) == 2 * len(models)
    for t in labels:
        x, y = t.get_position()
        (dy,) = [d for dx, d in diamonds if abs(dx - x) < 1e-9]
        assert t.get_va() == "bottom" and y >= dy + 2.5 and y >= float(t.get_text()) - 0.5
