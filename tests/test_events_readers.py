"""Event readers: every format round-trips generated recordings exactly; bad files give one line naming
the byte offset or event index.

The EVT 2.0 / EVT 3.0 decoders were checked once against two real Prophesee recordings (the sample
files of the expelliarmus project, data only): ``evt3_sample.raw`` decodes to 219,596 events at 1280x720
(gen4.1 sensor; x, y and polarity equal to that project's decoded ``evt3_sample.npy`` event for event;
its timestamps differ from ours after the first of nine places where the file's EVT_TIME_LOW steps back
by up to 11 us, which that decoder takes as a 4096 us wrap; the file's 551 EVT_TIME_HIGH words span
only 2861..2863, i.e. 8.8 ms, as ours), and ``evt2_sample.raw`` to 539,481 events at 640x480 (gen3).
Set CDNF_TI_EVENT_SAMPLES to a folder holding them to repeat the check.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from event_encoders import encode_aedat4, encode_dat, encode_evt2, encode_evt3, random_events, raw_header

from cdnf_ti.errors import InputError
from cdnf_ti.events import open_events, parse_sensor_size, prophesee as pr
from cdnf_ti.events.readers import is_event_file
from cdnf_ti.events.types import EVENT_DTYPE

SIZE = (64, 48)


def read_all(path) -> np.ndarray:
    return np.concatenate(list(open_events(path).chunks()))


@pytest.fixture
def small_blocks(monkeypatch):
    """Decode RAW files 64 bytes at a time, so the decoding state crosses many block boundaries."""
    monkeypatch.setattr(pr, "BLOCK_BYTES", 64)


def write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


# -- Prophesee ------------------------------------------------------------------------------------
def test_evt3_reader_returns_every_event_of_a_generated_recording(tmp_path, small_blocks):
    ev = random_events(4000, SIZE, seed=1)
    f = write(tmp_path / "rec.raw", raw_header({"evt": "3.0", "format": "EVT3;height=48;width=64"}) + encode_evt3(ev))
    ef = open_events(f)
    assert (ef.format, ef.sensor_size) == ("evt3", SIZE)
    np.testing.assert_array_equal(read_all(f), ev)


def test_evt3_vector_words_reach_the_right_pixels():
    # a run of 20 ON events on one row at one time: VECT_BASE_X, VECT_12, VECT_8
    ev = np.zeros(20, dtype=EVENT_DTYPE)
    ev["t"], ev["x"], ev["y"], ev["p"] = 5000, np.arange(3, 23), 7, 1
    words = np.frombuffer(encode_evt3(ev), dtype="<u2")
    assert sorted({int(w) >> 12 for w in words}) == [0x0, 0x3, 0x4, 0x5, 0x6, 0x8]
    np.testing.assert_array_equal(pr.decode_evt3(words, pr._Evt3State()), ev)


def test_evt3_time_base_wraps_after_2_to_the_24_us(tmp_path, small_blocks):
    ev = random_events(600, SIZE, duration_us=40_000_000, seed=2)  # 40 s: two wraps of the 16.8 s time base
    assert ev["t"][-1] > 2 * (1 << 24)
    f = write(tmp_path / "long.raw", raw_header({"evt": "3.0"}) + encode_evt3(ev))
    np.testing.assert_array_equal(read_all(f)["t"], ev["t"])


def test_evt2_reader_returns_every_event_of_a_generated_recording(tmp_path, small_blocks):
    ev = random_events(3000, SIZE, seed=3)
    f = write(tmp_path / "rec.raw", raw_header({"evt": "2.0", "geometry": "64x48"}) + encode_evt2(ev))
    ef = open_events(f)
    assert (ef.format, ef.sensor_size) == ("evt2", SIZE)
    np.testing.assert_array_equal(read_all(f), ev)


def test_dat_reader_returns_every_event(tmp_path):
    ev = random_events(2000, SIZE, seed=4)
    f = write(tmp_path / "rec.dat", encode_dat(ev, SIZE))
    ef = open_events(f)
    assert (ef.format, ef.sensor_size, ef.n_events) == ("dat", SIZE, ev.size)
    np.testing.assert_array_equal(read_all(f), ev)


def test_raw_header_sensor_size_from_a_known_plugin_name():
    h = pr.PropheseeHeader({"evt": "3.0", "plugin_name": "hal_plugin_imx636_evk4"})
    assert h.sensor_size == (1280, 720)
    assert pr.PropheseeHeader({"evt": "2.0"}).sensor_size is None


@pytest.mark.skipif(not os.environ.get("CDNF_TI_EVENT_SAMPLES"), reason="set CDNF_TI_EVENT_SAMPLES to the samples")
@pytest.mark.parametrize("name, count, size", [("evt3_sample.raw", 219_596, (1280, 720)),
                                               ("evt2_sample.raw", 539_481, (640, 480))])
def test_real_prophesee_samples_decode_to_their_published_counts(name, count, size):
    f = Path(os.environ["CDNF_TI_EVENT_SAMPLES"]) / name
    ev = read_all(f)
    assert ev.size == count
    assert open_events(f).sensor_size == size
    assert ev["x"].max() < size[0] and ev["y"].max() < size[1]


# -- AEDAT4, HDF5, NumPy --------------------------------------------------------------------------
def test_aedat4_reader_returns_every_event(tmp_path):
    pytest.importorskip("aedat")
    ev = random_events(2500, SIZE, seed=5)
    f = write(tmp_path / "rec.aedat4", encode_aedat4(ev, SIZE, packet_events=700))
    ef = open_events(f)
    assert (ef.format, ef.sensor_size) == ("aedat4", SIZE)
    np.testing.assert_array_equal(read_all(f), ev)


def test_dsec_hdf5_reader_adds_t_offset(tmp_path):
    h5py = pytest.importorskip("h5py")
    ev = random_events(2000, SIZE, seed=6)
    t_offset = 1_234_567
    f = tmp_path / "events.h5"
    with h5py.File(f, "w") as h:  # DSEC's layout, no sensor-size attributes (DSEC has none)
        for k in "xyp":
            h.create_dataset(f"events/{k}", data=ev[k])
        h.create_dataset("events/t", data=(ev["t"]).astype(np.uint32))
        h.create_dataset("t_offset", data=np.int64(t_offset))
        h.create_dataset("ms_to_idx", data=np.searchsorted(ev["t"], np.arange(0, 2001) * 1000).astype(np.uint64))
    ef = open_events(f)
    assert (ef.format, ef.sensor_size, ef.n_events) == ("hdf5", None, ev.size)
    got = read_all(f)
    np.testing.assert_array_equal(got["t"], ev["t"] + t_offset)
    for k in "xyp":
        np.testing.assert_array_equal(got[k], ev[k])


def test_npy_structured_array_is_read_with_polarity_as_on_off(tmp_path):
    ev = random_events(1000, SIZE, seed=7)
    a = np.zeros(ev.size, dtype=[("t", "<f8"), ("x", "<i2"), ("y", "<i2"), ("p", "<i1")])
    a["t"], a["x"], a["y"] = ev["t"], ev["x"], ev["y"]
    a["p"] = np.where(ev["p"] == 1, 1, -1)  # the -1/+1 convention
    np.save(tmp_path / "ev.npy", a)
    assert is_event_file(tmp_path / "ev.npy")
    np.testing.assert_array_equal(read_all(tmp_path / "ev.npy"), ev)


def test_npz_with_four_columns_is_read(tmp_path):
    ev = random_events(1000, SIZE, seed=8)
    np.savez_compressed(tmp_path / "ev.npz", t=ev["t"], x=ev["x"], y=ev["y"], p=ev["p"].astype(bool))
    np.testing.assert_array_equal(read_all(tmp_path / "ev.npz"), ev)


def test_a_frame_array_is_not_an_event_file(tmp_path):
    np.save(tmp_path / "frames.npy", np.zeros((3, 8, 8), dtype=np.uint8))
    assert not is_event_file(tmp_path / "frames.npy")


def test_sensor_size_option_parses_width_x_height():
    assert parse_sensor_size("640x480") == (640, 480)
    for bad in ("640", "0x480", "axb", "640x480x3"):
        with pytest.raises(ValueError):
            parse_sensor_size(bad)


# -- bad input --------------------------------------------------------------------------------------
def test_truncated_evt3_file_names_the_byte_offset(tmp_path):
    ev = random_events(500, SIZE, seed=9)
    head = raw_header({"evt": "3.0"})
    body = encode_evt3(ev)
    f = write(tmp_path / "cut.raw", head + body + b"\x12")  # half a word at the end
    with pytest.raises(InputError, match=f"truncated EVT 3.0 data.*byte offset {len(head) + len(body)}"):
        read_all(f)


def test_truncated_evt2_file_names_the_byte_offset(tmp_path):
    ev = random_events(500, SIZE, seed=10)
    head = raw_header({"evt": "2.0"})
    body = encode_evt2(ev)[:-3]
    f = write(tmp_path / "cut.raw", head + body)
    with pytest.raises(InputError, match=f"byte offset {len(head) + len(body) - 1}"):
        read_all(f)


def test_reserved_evt3_word_type_is_a_corrupt_file_at_its_byte_offset(tmp_path):
    head = raw_header({"evt": "3.0"})
    body = bytearray(encode_evt3(random_events(200, SIZE, seed=11)))
    body[41] = 0xB0  # high byte of word 20: type 0xB (reserved)
    f = write(tmp_path / "bad.raw", head + bytes(body))
    with pytest.raises(InputError, match=f"reserved word type 0xB at byte offset {len(head) + 40}"):
        read_all(f)


def test_truncated_aedat4_file_names_the_event_index(tmp_path):
    pytest.importorskip("aedat")
    data = encode_aedat4(random_events(2000, SIZE, seed=12), SIZE, packet_events=500)
    f = write(tmp_path / "cut.aedat4", data[:-100])
    with pytest.raises(InputError, match=r"truncated or corrupt AEDAT4 data after event \d+"):
        read_all(f)


def test_npy_without_event_fields_is_refused(tmp_path):
    np.save(tmp_path / "ev.npy", np.zeros(4, dtype=[("t", "<i8"), ("x", "<u2")]))
    with pytest.raises(InputError, match="lacks field"):
        open_events(tmp_path / "ev.npy")


def test_raw_file_without_encoding_is_refused(tmp_path):
    f = write(tmp_path / "x.raw", raw_header({"date": "today"}) + b"\0\0\0\0")
    with pytest.raises(InputError, match="names no encoding"):
        open_events(f)


def test_dsec_blosc_compressed_hdf5_is_read(tmp_path):
    h5py = pytest.importorskip("h5py")
    hdf5plugin = pytest.importorskip("hdf5plugin")
    ev = random_events(3000, SIZE, seed=13)
    f = tmp_path / "events.h5"
    with h5py.File(f, "w") as h:  # as DSEC ships them: Blosc (zstd) compression
        for k in "txyp":
            h.create_dataset(f"events/{k}", data=ev[k], **hdf5plugin.Blosc(cname="zstd", clevel=1))
        h.create_dataset("t_offset", data=np.int64(0))
    np.testing.assert_array_equal(read_all(f), ev)


def chunks_of(ev: np.ndarray, n: int):
    return iter([ev[i:i + n] for i in range(0, ev.size, n)])


def test_npy_writer_streams_chunks_and_reads_back(tmp_path):
    from cdnf_ti.events.writers import write_events

    ev = random_events(5000, SIZE, duration_us=50_000, seed=14)
    assert write_events(tmp_path / "ev.npy", chunks_of(ev, 777), SIZE) == ev.size
    np.testing.assert_array_equal(read_all(tmp_path / "ev.npy"), ev)


def test_hdf5_writer_streams_chunks_with_dsec_ms_to_idx(tmp_path):
    h5py = pytest.importorskip("h5py")
    from cdnf_ti.events.writers import write_events

    ev = random_events(5000, SIZE, duration_us=50_000, seed=15)
    assert write_events(tmp_path / "ev.h5", chunks_of(ev, 777), SIZE) == ev.size
    np.testing.assert_array_equal(read_all(tmp_path / "ev.h5"), ev)
    assert open_events(tmp_path / "ev.h5").sensor_size == SIZE
    with h5py.File(tmp_path / "ev.h5") as f:  # DSEC: ms_to_idx[m] = first event at or after m ms
        want = np.searchsorted(ev["t"], np.arange(len(f["ms_to_idx"])) * 1000, side="left")
        np.testing.assert_array_equal(f["ms_to_idx"][()], want)
        assert len(want) == ev["t"][-1] // 1000 + 2
