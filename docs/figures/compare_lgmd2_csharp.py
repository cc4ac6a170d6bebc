"""Run the LGMD2 authors' own C# code and cdnf_ti's LGMD2 on the same stimuli; compare frame by frame.

The authors' file is not part of this project (no licence for reuse): get
``lgmd2OpenSource.cs`` from the Fu lab's public repository (LGMD2-open-source)
yourself, install Mono's C# compiler (``apt-get install mono-mcs``), then

    PYTHONPATH=. python docs/figures/compare_lgmd2_csharp.py path/to/lgmd2OpenSource.cs [--grid full]

``--grid quick|full`` also runs their code on every stimulus of the
selectivity grid (:mod:`cdnf_ti.experiments.selectivity`) and counts the grid
points where their LGMD2 and ours differ in alerting (and first alert frame).

Both published versions of the file build: the class is ``lgmd2OpenSource`` in the July
2019 upload and ``LGMD2OpenSource`` since October 2019 (the equations are the same); the
driver subclasses whichever the file defines.

A small driver of ours (below) subclasses their class, feeds it the frames as
8-bit grey (``LGMD2_Processing(previous, current, t)`` for t = 1, 2, ...) and
prints its sigmoid membrane potential, SFA output, spikes, spike count and
collision flag per frame. The script prints, per stimulus, whether each
implementation alerts, and the largest per-frame differences.
"""
from __future__ import annotations

import re
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

DRIVER = r"""
using System;
namespace LGMD
{
    internal class Driver : BASE_CLASS
    {
        Driver(int w, int h, int fps) : base(w, h, fps) { }
        static void Main(string[] args)
        {
            byte[] raw = System.IO.File.ReadAllBytes(args[0]);
            int T = int.Parse(args[1]), H = int.Parse(args[2]), W = int.Parse(args[3]), fps = int.Parse(args[4]);
            var d = new Driver(W, H, fps);
            byte[,,] prev = null;
            for (int t = 0; t < T; t++)
            {
                var img = new byte[H, W, 1];
                for (int y = 0; y < H; y++) for (int x = 0; x < W; x++) img[y, x, 0] = raw[(t * H + y) * W + x];
                if (prev != null)
                {
                    d.LGMD2_Processing(prev, img, t);
                    int c = t % 2;
                    Console.WriteLine("{0} {1:R} {2:R} {3} {4} {5}", t, d.smp[c], d.sfa[c], d.spike, d.Nsp, d.collision);
                }
                prev = img;
            }
        }
    }
}
"""

#: (label, stimulus factory keyword arguments) compared by default.
CASES = [
    ("light receding, 120 px, 60 fps", dict(name="light_receding", height=120, width=120, fps=60.0)),
    ("light receding, 120 px, linear", dict(name="light_receding", height=120, width=120, expansion="linear")),
    ("light receding, 600 px, 3-550 px in 50 frames, linear",
     dict(name="light_receding", height=600, width=600, start_half_size=1.5, end_half_size=275.0,
          duration=50 / 30, expansion="linear")),
    ("dark looming, 240 px", dict(name="dark_looming", height=240, width=240)),
    ("dark translating, 120 px", dict(name="dark_translating", height=120, width=120)),
]


#: The LGMD2 class's name in the authors' file: ``lgmd2OpenSource`` until October 2019, then
#: ``LGMD2OpenSource``.
CLASS_NAMES = ("LGMD2OpenSource", "lgmd2OpenSource")


def lgmd2_class_name(source: str) -> str:
    """The name of the LGMD2 class that ``source`` (the authors' C# file) defines.

    Raises
    ------
    SystemExit
        With a one-line message when the file defines neither name.
    """
    for name in CLASS_NAMES:
        if re.search(rf"\bclass\s+{name}\b", source):
            return name
    raise SystemExit(f"error: the C# file defines no class named {' or '.join(CLASS_NAMES)}; "
                     "is it the authors' lgmd2OpenSource.cs?")


def build(cs_file: Path, work: Path) -> Path:
    base = lgmd2_class_name(cs_file.read_text(encoding="utf-8", errors="replace"))
    (work / "Driver.cs").write_text(DRIVER.replace("BASE_CLASS", base))
    exe = work / "lgmd2.exe"
    subprocess.run(["mcs", "-nowarn:0169,0414", f"-out:{exe}", str(cs_file), str(work / "Driver.cs")], check=True)
    return exe


def run_csharp(exe: Path, frames: np.ndarray, fps: int, work: Path) -> np.ndarray:
    raw = work / "frames.u8"
    frames.astype(np.uint8).tofile(raw)
    T, H, W = frames.shape
    out = subprocess.run(["mono", str(exe), str(raw), str(T), str(H), str(W), str(fps)], check=True,
                         capture_output=True, text=True).stdout
    return np.array([[float(v) for v in line.split()] for line in out.splitlines() if line.strip()])


def compare_grid(exe: Path, work: Path, which: str) -> None:
    from cdnf_ti.experiments.selectivity import grid, make_grid_stimulus
    from cdnf_ti.models import create_model

    n = same = 0
    light_receding_alerts = []
    for p in grid(which):
        s = make_grid_stimulus(p)
        frames = np.stack([np.rint(f * 255.0).astype(np.uint8) for f in s.frames()])
        cs = run_csharp(exe, frames, int(s.fps), work)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tr = create_model("lgmd2", backend="taichi", fps=s.fps).run(iter(frames), progress=False)
        first_cs = int(cs[np.argmax(cs[:, 5] > 0), 0]) if cs[:, 5].max() > 0 else None
        n += 1
        ok = first_cs == tr.first_alert
        same += ok
        if p.stimulus == "light_receding" and first_cs is not None:
            light_receding_alerts.append(f"{p.parameter}={p.value}")
        if not ok:
            print(f"  differs: {p.stimulus} {p.parameter}={p.value}: authors {first_cs}, cdnf_ti {tr.first_alert}")
    print(f"grid {which}: {same}/{n} stimuli with the same first alert frame (or none) in both; "
          f"authors' code alerts on light receding at: {', '.join(light_receding_alerts) or 'none'}")


def main(argv: list[str]) -> int:
    from cdnf_ti.models import create_model
    from cdnf_ti.stimuli.basic import basic_stimulus

    cs_file = Path(argv[0])
    which = argv[argv.index("--grid") + 1] if "--grid" in argv else None
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        exe = build(cs_file, work)
        for label, kw in CASES:
            s = basic_stimulus(**kw)
            frames = np.stack([np.rint(f * 255.0).astype(np.uint8) for f in s.frames()])
            cs = run_csharp(exe, frames, int(s.fps), work)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                tr = create_model("lgmd2", backend="numpy", fps=s.fps).run(iter(frames), progress=False)
            d = tr.diagnostics
            ours = np.column_stack([tr.output[1:], d["Kh"][1:], d["n"][1:], d["count"][1:], tr.spike[1:]])
            their_alert = int(cs[:, 5].max()) if len(cs) else 0
            first_cs = int(cs[np.argmax(cs[:, 5] > 0), 0]) if their_alert else None
            print(f"{label}: authors' code alerts={their_alert} (first frame {first_cs}); "
                  f"cdnf_ti alerts={int(tr.first_alert is not None)} (first frame {tr.first_alert}); "
                  f"max |dK|={np.abs(ours[:, 0] - cs[:, 1]).max():.2e}, max |dKh|={np.abs(ours[:, 1] - cs[:, 2]).max():.2e}, "
                  f"spikes equal={np.array_equal(ours[:, 2], cs[:, 3])}, counts equal={np.array_equal(ours[:, 3], cs[:, 4])}, "
                  f"alerts equal={np.array_equal(ours[:, 4].astype(int), cs[:, 5].astype(int))}")
        if which:
            compare_grid(exe, work, which)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
