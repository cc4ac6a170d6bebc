"""Labels CSV: reading by header name, and every rejection naming its row."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cdnf_ti.errors import InputError
from cdnf_ti.experiments.labels import find_clip, read_labels, validate_dataset
from cdnf_ti.experiments.synthetic import write_video


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "labels.csv"
    p.write_text(text)
    return p


def _video(folder: Path, name: str, n: int = 12) -> Path:
    frames = [np.full((24, 32), k / (n + 1), np.float32) for k in range(n)]
    return write_video(folder / f"{name}.avi", frames)


def test_columns_are_found_by_header_name_and_extra_columns_ignored(tmp_path):
    p = _write(tmp_path, "notes,window_end,clip,frames,label,window_start,contact_frame\n"
                         "x,20,a,30,collision,10,18\n"
                         "y,,b,30,non-collision,,\n")
    a, b = read_labels(p)
    assert (a.clip, a.collision, a.window_start, a.window_end, a.contact_frame) == ("a", True, 10, 20, 18)
    assert (b.clip, b.collision, b.window_start, b.window_end, b.contact_frame) == ("b", False, None, None, None)


def test_contact_frame_column_is_optional(tmp_path):
    (lab,) = read_labels(_write(tmp_path, "clip,label,window_start,window_end\na,collision,3,5\n"))
    assert lab.contact_frame is None


def test_near_miss_counts_as_non_collision(tmp_path):
    (lab,) = read_labels(_write(tmp_path, "clip,label,window_start,window_end\na,near-miss,,\n"))
    assert lab.collision is False and lab.label == "near-miss"


@pytest.mark.parametrize("row, words", [
    ("a,collision,20,10", ["row 2", "window_start 20 > window_end 10"]),
    ("a,crash,1,2", ["row 2", "label 'crash'"]),
    ("a,collision,,", ["row 2", "needs window_start and window_end"]),
    ("a,non-collision,1,2", ["row 2", "empty window"]),
    ("a,collision,1.5,4", ["row 2", "whole frame"]),
    ("a,collision,x,4", ["row 2", "not a frame number"]),
    ("a,collision,-1,4", ["row 2", "negative"]),
    (",collision,1,4", ["row 2", "empty clip name"]),
])
def test_bad_rows_are_rejected_naming_the_row(tmp_path, row, words):
    p = _write(tmp_path, "clip,label,window_start,window_end\n" + row + "\n")
    with pytest.raises(InputError) as e:
        read_labels(p)
    msg = str(e.value)
    assert msg.startswith(str(p)) and "\n" not in msg
    for w in words:
        assert w in msg


def test_duplicate_clip_is_rejected_naming_both_rows(tmp_path):
    p = _write(tmp_path, "clip,label,window_start,window_end\na,non-collision,,\nb,non-collision,,\n"
                         "a,non-collision,,\n")
    with pytest.raises(InputError, match=r"row 4: clip 'a' is already labelled in row 2"):
        read_labels(p)


def test_missing_required_column_is_rejected(tmp_path):
    p = _write(tmp_path, "clip,label,window_start\na,non-collision,\n")
    with pytest.raises(InputError, match="window_end"):
        read_labels(p)


def test_missing_or_empty_labels_file_is_rejected(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_labels(tmp_path / "nope.csv")
    with pytest.raises(InputError, match="no rows"):
        read_labels(_write(tmp_path, "clip,label,window_start,window_end\n"))


def test_a_folder_given_as_labels_file_is_named_as_such(tmp_path):
    with pytest.raises(InputError, match="is a folder, not a labels CSV file"):
        read_labels(tmp_path)


def test_unknown_clip_is_rejected_naming_the_row(tmp_path):
    _video(tmp_path, "a")
    p = _write(tmp_path, "clip,label,window_start,window_end\na,collision,2,5\nghost,non-collision,,\n")
    with pytest.raises(InputError, match=r"row 3: clip 'ghost' has no video"):
        validate_dataset(read_labels(p), tmp_path, p)


@pytest.mark.parametrize("cols, row", [("window_start,window_end", "5,12"),
                                       ("window_start,window_end", "12,13"),
                                       ("window_start,window_end,contact_frame", "2,5,40")])
def test_window_outside_the_video_is_rejected(tmp_path, cols, row):
    _video(tmp_path, "a", n=12)
    p = _write(tmp_path, f"clip,label,{cols}\na,collision,{row}\n")
    with pytest.raises(InputError, match=r"row 2 \(a\): \w+ \d+ is outside the video \(frames 0..11\)"):
        validate_dataset(read_labels(p), tmp_path, p)


def test_window_on_the_last_frame_is_accepted(tmp_path):
    _video(tmp_path, "a", n=12)
    p = _write(tmp_path, "clip,label,window_start,window_end\na,collision,0,11\n")
    files = validate_dataset(read_labels(p), tmp_path, p)
    assert files["a"].name == "a.avi"


def test_corrupt_clip_is_left_for_the_run_to_report(tmp_path):
    (tmp_path / "bad.mp4").write_bytes(b"this is not a video" * 50)
    p = _write(tmp_path, "clip,label,window_start,window_end\nbad,collision,1,2\n")
    assert validate_dataset(read_labels(p), tmp_path, p)["bad"].name == "bad.mp4"


def test_a_clip_name_matching_two_videos_is_rejected_and_the_file_name_settles_it(tmp_path):
    _video(tmp_path, "a")
    np.save(tmp_path / "a.npy", np.zeros((12, 24, 32), np.float32))
    p = _write(tmp_path, "clip,label,window_start,window_end\na,collision,2,5\n")
    with pytest.raises(InputError, match=r"row 2 \(a\): clip 'a' matches several videos in .*: a\.avi, a\.npy"):
        validate_dataset(read_labels(p), tmp_path, p)
    p = _write(tmp_path, "clip,label,window_start,window_end\na.npy,collision,2,5\n")
    assert validate_dataset(read_labels(p), tmp_path, p)["a.npy"].name == "a.npy"


def test_find_clip_prefers_exact_name_then_known_extensions(tmp_path):
    _video(tmp_path, "x")
    (tmp_path / "x.csv").write_text("not a clip")
    assert find_clip(tmp_path, "x").name == "x.avi"
    assert find_clip(tmp_path, "x.avi").name == "x.avi"
    assert find_clip(tmp_path, "y") is None


def test_every_bad_row_is_listed_each_with_a_hint_in_one_line(tmp_path):
    p = _write(tmp_path, "clip,label,window_start,window_end,contact_frame\n"
                         "a,colision,1,2,\n"          # row 2: bad label
                         "b,collision,9,3,\n"         # row 3: window reversed
                         "c,collision,1,2,\n"         # row 4: fine
                         "d,non-collision,4,5,\n"     # row 5: window on a non-collision clip
                         "e,collision,x,2.5,\n")      # row 6: two bad frame numbers
    with pytest.raises(InputError) as e:
        read_labels(p)
    msg = str(e.value)
    assert "\n" not in msg and "4 bad rows" in msg
    for row in ("row 2 (a)", "row 3 (b)", "row 5 (d)", "row 6 (e)"):
        assert row in msg
    assert "row 4" not in msg
    assert "window_start 'x'" in msg and "window_end '2.5'" in msg
    assert msg.count("(hint: ") == 5


def test_every_missing_clip_and_window_past_the_end_is_listed(tmp_path):
    _video(tmp_path, "a", n=12)
    p = _write(tmp_path, "clip,label,window_start,window_end\na,collision,5,20\nb,non-collision,,\n"
                         "c,non-collision,,\n")
    with pytest.raises(InputError) as e:
        validate_dataset(read_labels(p), tmp_path, p)
    msg = str(e.value)
    assert "3 bad rows" in msg and "window_end 20 is outside the video" in msg
    assert "clip 'b' has no video" in msg and "clip 'c' has no video" in msg and "hint:" in msg


def test_every_kind_of_bad_row_is_reported_in_one_pass(tmp_path, capsys):
    """A bad value, a clip with no video and a window past the video's end, all in one error line."""
    from cdnf_ti.run import main

    _video(tmp_path, "a", n=12)
    _video(tmp_path, "c", n=12)
    p = _write(tmp_path, "clip,label,window_start,window_end\n"
                         "a,collision,5,20\n"          # row 2: window past the end
                         "b,non-collision,,\n"         # row 3: no video
                         "c,colision,,\n")             # row 4: bad label
    assert main(["dataset", str(tmp_path), "--labels", str(p), "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    errors = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and "3 bad rows" in errors[0]
    assert errors[0].index("row 2 (a)") < errors[0].index("row 3") < errors[0].index("row 4 (c)")
    assert "outside the video" in errors[0] and "no video" in errors[0] and "label 'colision'" in errors[0]


def test_a_row_with_a_bad_label_and_a_bad_frame_reports_both(tmp_path):
    p = _write(tmp_path, "clip,label,window_start,window_end\na,colision,x,2\n")
    with pytest.raises(InputError) as e:
        read_labels(p)
    assert "label 'colision'" in str(e.value) and "window_start 'x'" in str(e.value)


def test_an_unclosed_quote_is_named_as_the_cause(tmp_path):
    p = _write(tmp_path, 'clip,label,window_start,window_end\na,collision,1,2\nb,"non-collision,,\nc,collision,3,4\n')
    with pytest.raises(InputError) as e:
        read_labels(p)
    msg = str(e.value)
    assert "row 3" in msg and "quote" in msg and "never closed" in msg and "\n" not in msg
