"""Frame conversion and inputs: videos, image folders, .npy arrays, and their errors."""
import cv2
import numpy as np
import pytest

from cdnf_ti.errors import InputError
from cdnf_ti.frames import iter_grey, open_source, to_grey


def write_video(path, frames, fps=30.0, fourcc="mp4v"):
    h, w = frames[0].shape[:2]
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (w, h))
    assert vw.isOpened()
    for f in frames:
        vw.write(f if f.ndim == 3 else cv2.cvtColor(f, cv2.COLOR_GRAY2BGR))
    vw.release()


def _frames(n=6, h=32, w=48):
    rng = np.random.default_rng(1)
    return [rng.integers(0, 255, (h, w, 3), dtype=np.uint8) for _ in range(n)]


def test_bgr_is_converted_with_bt601_luma_weights():
    bgr = np.zeros((4, 4, 3), np.uint8)
    bgr[..., 0], bgr[..., 1], bgr[..., 2] = 200, 100, 50
    g = to_grey(bgr)
    assert g.dtype == np.uint8
    assert int(g[0, 0]) == round(0.114 * 200 + 0.587 * 100 + 0.299 * 50)


def test_grey_float_frames_pass_through_as_float32():
    f = np.linspace(0, 1, 64, dtype=np.float64).reshape(8, 8)
    g = to_grey(f)
    assert g.dtype == np.float32 and np.allclose(g, f)


@pytest.mark.parametrize("bad", [np.zeros((4, 4, 2), np.uint8), np.zeros((4,), np.uint8),
                                 np.zeros((4, 4), np.int32), np.full((4, 4), -0.5)])
def test_unsupported_frames_raise_value_error(bad):
    with pytest.raises(ValueError):
        to_grey(bad)


def test_video_file_is_read_frame_by_frame(tmp_path):
    path = tmp_path / "clip.mp4"
    write_video(path, _frames(7))
    src = open_source(path)
    assert src.shape == (32, 48) and src.fps == pytest.approx(30.0)
    frames = list(iter_grey(src))
    assert len(frames) == 7 and frames[0].dtype == np.uint8
    assert len(list(iter_grey(src))) == 7  # re-iterable


def test_image_folder_is_read_in_sorted_order(tmp_path):
    for i in (2, 0, 1):
        cv2.imwrite(str(tmp_path / f"f{i:03d}.png"), np.full((10, 12), 10 * i, np.uint8))
    frames = list(iter_grey(open_source(tmp_path)))
    assert [int(f[0, 0]) for f in frames] == [0, 10, 20]


def test_npy_array_is_read(tmp_path):
    arr = np.random.default_rng(0).random((5, 16, 20)).astype(np.float32)
    np.save(tmp_path / "a.npy", arr)
    frames = list(iter_grey(open_source(tmp_path / "a.npy")))
    assert len(frames) == 5 and np.array_equal(frames[3], arr[3])


def test_missing_file_error_names_the_file(tmp_path):
    with pytest.raises(InputError, match=r"nope\.mp4: no such file"):
        open_source(tmp_path / "nope.mp4")


def test_empty_file_error_names_the_file(tmp_path):
    p = tmp_path / "empty.mp4"
    p.write_bytes(b"")
    with pytest.raises(InputError, match=r"empty\.mp4: file is empty"):
        open_source(p)


def test_corrupt_video_error_names_the_file(tmp_path):
    p = tmp_path / "corrupt.mp4"
    p.write_bytes(np.random.default_rng(0).integers(0, 255, 5000, dtype=np.uint8).tobytes())
    with pytest.raises(InputError, match=r"corrupt\.mp4: "):
        list(iter_grey(open_source(p)))


def test_truncated_video_is_an_error(tmp_path):
    good = tmp_path / "good.avi"
    write_video(good, _frames(30), fourcc="MJPG")
    data = good.read_bytes()
    cut = tmp_path / "cut.avi"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match=r"cut\.avi: "):
        list(iter_grey(open_source(cut)))


def test_folder_without_images_is_an_error(tmp_path):
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(InputError, match="no image files"):
        open_source(tmp_path)


def test_frame_size_change_in_folder_is_an_error_naming_the_image(tmp_path):
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((10, 12), np.uint8))
    cv2.imwrite(str(tmp_path / "b.png"), np.zeros((11, 12), np.uint8))
    with pytest.raises(InputError, match=r"b\.png: .*size changed"):
        list(iter_grey(open_source(tmp_path)))


def test_npy_with_wrong_shape_is_an_error(tmp_path):
    np.save(tmp_path / "bad.npy", np.zeros((4, 4)))
    with pytest.raises(InputError, match=r"bad\.npy: .*shape"):
        open_source(tmp_path / "bad.npy")


def test_npy_with_out_of_range_floats_is_an_error_naming_frame(tmp_path):
    np.save(tmp_path / "hot.npy", np.full((3, 8, 8), 3.0, np.float32))
    with pytest.raises(InputError, match=r"hot\.npy: frame 0: .*\[0, 1\]"):
        list(iter_grey(open_source(tmp_path / "hot.npy")))


def test_not_a_numpy_file_is_an_error(tmp_path):
    p = tmp_path / "junk.npy"
    p.write_bytes(b"definitely not numpy")
    with pytest.raises(InputError, match=r"junk\.npy: not a NumPy \.npy array file"):
        open_source(p)


def test_background_decoding_yields_the_same_frames_in_order(tmp_path):
    path = tmp_path / "clip.avi"
    write_video(path, _frames(12), fourcc="MJPG")
    src = open_source(path)
    inline = list(iter_grey(src, prefetch=0))
    ahead = list(iter_grey(src, prefetch=3))
    assert len(ahead) == 12
    assert all(np.array_equal(a, b) for a, b in zip(inline, ahead))


def test_background_decoding_reraises_errors_in_the_caller(tmp_path):
    np.save(tmp_path / "hot.npy", np.concatenate([np.zeros((2, 8, 8)), np.full((1, 8, 8), 3.0)]).astype(np.float32))
    it = iter_grey(open_source(tmp_path / "hot.npy"), prefetch=2)
    assert next(it).shape == (8, 8) and next(it).shape == (8, 8)
    with pytest.raises(InputError, match=r"hot\.npy: frame 2"):
        next(it)


def test_closing_a_prefetched_stream_early_stops_its_thread():
    import threading

    from cdnf_ti.frames import prefetched

    produced = []

    def endless():
        i = 0
        while True:
            produced.append(i)
            yield i
            i += 1

    it = prefetched(endless(), depth=2)
    assert [next(it) for _ in range(3)] == [0, 1, 2]
    it.close()
    assert not any(t.name == "cdnf_ti-decode" and t.is_alive() for t in threading.enumerate())
    assert len(produced) <= 3 + 2 + 2
