"""Every file reader, fed anything: a result or the project's error (RigctlError), never another exception,
within bounded memory (tracemalloc's peak). Time is bounded by the same limits (file size, aliases, values
after expansion, timecode span), not asserted with a clock: CI shares two cores with other work.

Inputs are both arbitrary bytes and mutations of a valid file (a valid file with one value, line or byte
changed reaches far deeper into a reader than random bytes do).
"""

from __future__ import annotations

import re
import tracemalloc
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from rigctl.calibration_model import load_calibration
from rigctl.depth.grid_folder import load_grid_folder
from rigctl.errors import RigctlError
from rigctl.exr import read_exr, write_exr
from rigctl.pfm import read_pfm
from rigctl.rig import load_rig
from rigctl.take.index import RECORD_SIZE, pack_into, read_index
from rigctl.take.reader import TakeReader

REPO = Path(__file__).resolve().parents[2]
RIG_TEXT = (REPO / "rigs" / "sim-3x3.yaml").read_text()
MEMORY_BOUND = 64 << 20  # bytes allocated by one read at most (the inputs are a few kB)
PROPERTY = settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)

# YAML values a careless or hostile writer puts where a number or a mapping belongs
VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=20),
    st.lists(st.integers(-5, 5), max_size=4),
    st.dictionaries(st.text(max_size=5), st.integers(), max_size=3),
)


def bounded(read: Callable[[], Any]) -> None:
    """Run ``read``: it returns or raises RigctlError (anything else fails the test), within MEMORY_BOUND."""
    tracemalloc.start()
    try:
        read()
    except RigctlError as exc:
        assert str(exc) and "\n" not in str(exc)  # one line
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    assert peak < MEMORY_BOUND


def mutate_yaml(data: Any, path: list[Any], value: Any) -> Any:
    """``data`` with the value found by following ``path`` (indices taken modulo the size) replaced."""
    if not path or not isinstance(data, dict | list) or not data:
        return value
    if isinstance(data, dict):
        key = list(data)[path[0] % len(data)]
        return {**data, key: mutate_yaml(data[key], path[1:], value)}
    i = path[0] % len(data)
    return [*data[:i], mutate_yaml(data[i], path[1:], value), *data[i + 1 :]]


PATHS = st.lists(st.integers(0, 50), min_size=1, max_size=4)


# ---- YAML files ---------------------------------------------------------------------------------------------


@PROPERTY
@given(text=st.text(max_size=400))
def test_rig_file_any_text(tmp_path: Path, text: str) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text(text, encoding="utf-8")
    bounded(lambda: load_rig(path))


@PROPERTY
@given(where=PATHS, value=VALUES)
def test_rig_file_one_value_changed(tmp_path: Path, where: list[int], value: Any) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(mutate_yaml(yaml.safe_load(RIG_TEXT), where, value)))
    bounded(lambda: load_rig(path))


@PROPERTY
@given(line=st.integers(0, 200), text=st.text(max_size=40))
def test_rig_file_one_line_changed(tmp_path: Path, line: int, text: str) -> None:
    lines = RIG_TEXT.splitlines()
    lines[line % len(lines)] = text
    path = tmp_path / "rig.yaml"
    path.write_text("\n".join(lines), encoding="utf-8")
    bounded(lambda: load_rig(path))


@settings(PROPERTY, max_examples=15)
@given(width=st.integers(1, 12), depth=st.integers(1, 12))
def test_alias_bombs_of_any_shape_are_refused_in_bounded_memory(tmp_path: Path, width: int, depth: int) -> None:
    lines = ["spec: 1", "l0: &l0 [x]"]
    for d in range(1, depth + 1):
        lines.append(f"l{d}: &l{d} [{', '.join([f'*l{d - 1}'] * width)}]")
    path = tmp_path / "rig.yaml"
    path.write_text("\n".join(lines))
    bounded(lambda: load_rig(path))


@pytest.fixture(scope="module")
def calibration_text(module_tmp: Callable[[str], Path]) -> str:
    cams = {}
    for r in range(2):
        for c in range(2):
            cams[f"r{r}c{c}"] = {
                "K": [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]],
                "dist": [-0.1, 0.01, 0.0, 0.0, 0.0],
                "R": np.eye(3).tolist(),
                "t": [-0.1 * c, -0.1 * r, 0.0],
                "image_size": [640, 480],
            }
    return yaml.safe_dump({"spec": 1, "rig": "test", "reference_camera": "r0c0", "cameras": cams})


@PROPERTY
@given(where=PATHS, value=VALUES)
def test_calibration_one_value_changed(tmp_path: Path, calibration_text: str, where: list[int], value: Any) -> None:
    path = tmp_path / "calibration.yaml"
    path.write_text(yaml.safe_dump(mutate_yaml(yaml.safe_load(calibration_text), where, value)))
    bounded(lambda: load_calibration(path))


@PROPERTY
@given(text=st.text(max_size=300))
def test_calibration_any_text(tmp_path: Path, text: str) -> None:
    path = tmp_path / "calibration.yaml"
    path.write_text(text, encoding="utf-8")
    bounded(lambda: load_calibration(path))


CALIBRATION = """spec: 1
cameras:
  r0c0:
    K: [[1000, 0, 320], [0, 1000, 240], [0, 0, 1]]
    dist: [0, 0, 0, 0, 0]
    R: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    t: [0, 0, 0]
    image_size: [640, 480]
"""


@pytest.mark.parametrize(
    ("old", "says"),
    [
        ("[[1000, 0, 320]", "cameras.r0c0.K must be 3x3 finite numbers"),
        ("[0, 0, 0, 0, 0]", "cameras.r0c0.dist must be a list of finite numbers"),
        ("t: [0, 0, 0]", "cameras.r0c0.t must be 3 finite numbers"),
        ("[640, 480]", "cameras.r0c0.image_size must be [width, height], at most 65536 px a side"),
    ],
    ids=["K", "dist", "t", "image_size"],
)
def test_calibration_integer_too_large_for_a_float_is_named(tmp_path: Path, old: str, says: str) -> None:
    """A 401-digit integer in a calibration ended rectify (and every reader of it) in an OverflowError traceback."""
    from rigctl.errors import RigFileError

    path = tmp_path / "calibration.yaml"
    path.write_text(CALIBRATION)
    load_calibration(path)  # the file as it is reads
    path.write_text(CALIBRATION.replace(old, old.replace("0", "1" + "0" * 400, 1), 1))
    with pytest.raises(RigFileError, match=re.escape(says)):
        load_calibration(path)


@PROPERTY
@given(
    spec=st.dictionaries(
        st.sampled_from(["spacing_x", "spacing_y", "focal_px", "doffs", "disparity_range_px"]), VALUES, max_size=5
    )
)
def test_grid_yaml_any_values(tmp_path: Path, spec: dict[str, Any]) -> None:
    import cv2

    (tmp_path / "grid.yaml").write_text(yaml.safe_dump(spec))
    cv2.imwrite(str(tmp_path / "r0c0.png"), np.zeros((4, 6, 3), np.uint8))
    bounded(lambda: load_grid_folder(tmp_path))


# ---- takes ----------------------------------------------------------------------------------------------------


def small_take(folder: Path, frames: int = 2) -> dict[str, Any]:
    from rigctl.interfaces import Frame, FrameFlags
    from rigctl.take.manifest import Manifest, write_manifest
    from rigctl.take.writer import CameraWriter

    folder.mkdir(parents=True, exist_ok=True)
    w = CameraWriter("r0c0", folder / "cameras", 25.0, sync_interval_s=0)
    for i in range(frames):
        w.write(Frame("r0c0", i, i * 40_000_000, i * 40_000_000, FrameFlags(0), memoryview(bytes([i]) * 32)))
    w.close()
    manifest = {
        "spec": 1,
        "take": "t",
        "status": "complete",
        "format": {"width": 4, "height": 4, "pixel_format": "UYVY", "fps": 25.0, "bytes_per_frame": 32},
        "cameras": {"r0c0": {"essence": "cameras/r0c0.essence", "index": "cameras/r0c0.index", "frames": frames}},
    }
    write_manifest(folder, Manifest.model_validate(manifest))
    return manifest


def read_whole_take(folder: Path) -> None:
    reader = TakeReader(folder)
    reader.summary()
    for name in reader.names:
        for i in range(len(reader.index[name])):
            reader.frame_rgb(name, i)


@PROPERTY
@given(where=PATHS, value=VALUES)
@example(where=[34, 0, 0], value="\x00")  # a NUL in a camera's file name (found in a worktree's database)
def test_take_yaml_one_value_changed(module_tmp: Callable[[str], Path], where: list[int], value: Any) -> None:
    folder = module_tmp("take")
    manifest = small_take(folder)
    (folder / "take.yaml").write_text(yaml.safe_dump(mutate_yaml(manifest, where, value)))
    bounded(lambda: read_whole_take(folder))


@PROPERTY
@given(text=st.text(max_size=300))
def test_take_yaml_any_text(module_tmp: Callable[[str], Path], text: str) -> None:
    folder = module_tmp("take")
    small_take(folder)
    (folder / "take.yaml").write_text(text, encoding="utf-8")
    bounded(lambda: read_whole_take(folder))


@PROPERTY
@given(data=st.binary(max_size=4 * RECORD_SIZE + 7))
def test_index_any_bytes(tmp_path: Path, data: bytes) -> None:
    path = tmp_path / "x.index"
    path.write_bytes(data)
    bounded(lambda: read_index(path, 1000))


@PROPERTY
@given(
    fields=st.tuples(
        st.integers(0, 2**64 - 1),  # sequence
        st.integers(-(2**63), 2**63 - 1),  # capture
        st.integers(0, 2**64 - 1),  # offset
        st.integers(0, 2**32 - 1),  # size
        st.integers(0, 2**32 - 1),  # crc
        st.integers(-(2**31), 2**31 - 1),  # frame set
        st.integers(0, 2**32 - 1),  # timecode
        st.integers(0, 2**16 - 1),  # flags
    )
)
def test_take_with_any_well_formed_index_record(
    module_tmp: Callable[[str], Path], fields: tuple[int, ...]
) -> None:
    """A record whose own checksum is right but whose values are anything: offsets, sizes, flags."""
    folder = module_tmp("take")
    small_take(folder, frames=1)
    seq, cap, off, size, crc, fset, tc, flags = fields
    buf = bytearray(RECORD_SIZE)
    pack_into(buf, seq, cap, cap, flags, off, size, crc, fset, tc)
    (folder / "cameras" / "r0c0.index").write_bytes(bytes(buf))
    bounded(lambda: read_whole_take(folder))


# ---- images ---------------------------------------------------------------------------------------------------


@PROPERTY
@given(data=st.binary(max_size=200))
def test_pfm_any_bytes(tmp_path: Path, data: bytes) -> None:
    path = tmp_path / "x.pfm"
    path.write_bytes(data)
    bounded(lambda: read_pfm(path))


@PROPERTY
@given(header=st.binary(max_size=40), pixels=st.binary(max_size=64))
def test_pfm_any_header(tmp_path: Path, header: bytes, pixels: bytes) -> None:
    path = tmp_path / "x.pfm"
    path.write_bytes(b"Pf\n" + header + b"\n" + pixels)
    bounded(lambda: read_pfm(path))


@pytest.fixture(scope="module")
def exr_bytes(module_tmp: Callable[[str], Path]) -> bytes:
    path = module_tmp("exr") / "x.exr"
    write_exr(path, {"RGB": np.full((4, 5, 3), 0.5, np.float32)}, {"rigctl:camera": "r0c0"})
    # the written file reads back
    channels, _ = read_exr(path)
    assert np.allclose(channels["RGB"], 0.5)
    return path.read_bytes()


@PROPERTY
@given(at=st.integers(0, 400), value=st.binary(min_size=1, max_size=8))
def test_exr_header_bytes_changed(tmp_path: Path, exr_bytes: bytes, at: int, value: bytes) -> None:
    at %= min(len(exr_bytes), 400)  # the header and the offset table
    path = tmp_path / "x.exr"
    path.write_bytes(exr_bytes[:at] + value + exr_bytes[at + len(value) :])
    bounded(lambda: read_exr(path))


@PROPERTY
@given(cut=st.integers(0, 400))
def test_exr_cut_short(tmp_path: Path, exr_bytes: bytes, cut: int) -> None:
    path = tmp_path / "x.exr"
    path.write_bytes(exr_bytes[:cut])
    bounded(lambda: read_exr(path))


@PROPERTY
@given(timecodes=st.lists(st.integers(0, 2**32 - 1), min_size=1, max_size=4))
def test_take_with_any_timecodes(module_tmp: Callable[[str], Path], timecodes: list[int]) -> None:
    """Frame sets by timecode hold one slot per timecode between the first and the last: any timecodes a
    damaged or hostile index holds are read in bounded memory."""
    from rigctl.interfaces import FrameFlags

    folder = module_tmp("take")
    small_take(folder, frames=len(timecodes))
    records = b""
    for i, tc in enumerate(timecodes):
        buf = bytearray(RECORD_SIZE)
        crc = zlib.crc32(bytes([i]) * 32)
        pack_into(buf, i, i * 40_000_000, i * 40_000_000, int(FrameFlags.TIMECODE), i * 32, 32, crc, -1, tc)
        records += bytes(buf)
    (folder / "cameras" / "r0c0.index").write_bytes(records)
    bounded(lambda: read_whole_take(folder))


@pytest.mark.parametrize(
    ("line", "says"),
    [
        ("spacing_x: 0", "spacing_x: must be positive, got 0"),
        ("spacing_x: -0.12", "spacing_x: must be positive, got -0.12"),
        ("spacing_x: .nan", "spacing_x: must be a finite number, got nan"),
        ("spacing_x: '0.12'", "spacing_x: must be a finite number, got '0.12'"),
        ("spacing_x: 0.12\nspacing_y: -1", "spacing_y: must be positive, got -1"),
        # an integer too large for a float: math.isfinite raised OverflowError (a traceback)
        pytest.param("spacing_x: 1" + "0" * 400, "spacing_x: must be a finite number, got 1000", id="int-spacing"),
        pytest.param(
            "spacing_x: 1\ndisparity_range_px: [0, 1" + "0" * 400 + "]", "disparity_range_px: expected", id="int-range"
        ),
    ],
)
def test_a_grid_yaml_value_out_of_range_is_named(tmp_path: Path, line: str, says: str) -> None:
    """A zero or negative spacing was reported as 'must be numbers' (it is a number)."""
    import cv2

    from rigctl.errors import RigFileError

    focal = "" if "focal_px" in line else "\nfocal_px: 1000"
    (tmp_path / "grid.yaml").write_text(line + focal + "\n")
    cv2.imwrite(str(tmp_path / "r0c0.png"), np.zeros((4, 6, 3), np.uint8))
    with pytest.raises(RigFileError, match=re.escape(says)):
        load_grid_folder(tmp_path)


@pytest.mark.parametrize(
    ("spec", "says"),
    [
        ("focal_px: 1.0e+300", "focal_px: 1e+300 is not plausible for pictures 24 px wide (expected 1.2 to 2400 px)"),
        ("focal_px: 1.0e-300", "focal_px: 1e-300 is not plausible for pictures 24 px wide"),
        ("focal_px: 100\nspacing_x: 1.0e-300", "spacing_x: must be between 1e-06 and 1e+06, got 1e-300"),
        ("focal_px: 100\nspacing_x: 1.0e+300", "spacing_x: must be between 1e-06 and 1e+06, got 1e+300"),
        ("focal_px: 100\nspacing_y: 1.0e+300", "spacing_y: must be between 1e-06 and 1e+06, got 1e+300"),
        ("focal_px: 100\ndoffs: -1.0e+300", "doffs: must be within +-16384 px, got -1e+300"),
        ("focal_px: 100\nspacing_y: 0", "spacing_y: 0 puts the 2 rows of cameras at one place"),
    ],
)
def test_grid_yaml_numbers_that_make_every_depth_zero_or_infinite_are_refused(
    tmp_path: Path, spec: str, says: str
) -> None:
    """focal_px 1e300 (or 1e-300), a spacing of 1e300 or a doffs of 1e300 were accepted: every depth.Z came out
    0 and the EXR's worldToNDC infinite, with exit 0; spacing_y 0 was read as spacing_x."""
    import cv2

    from rigctl.errors import RigFileError

    (tmp_path / "grid.yaml").write_text("spacing_x: 1\n" * ("spacing_x" not in spec) + spec + "\n")
    for cam in ("r0c0", "r1c0"):
        cv2.imwrite(str(tmp_path / f"{cam}.png"), np.zeros((16, 24, 3), np.uint8))
    with pytest.raises(RigFileError, match=re.escape(says)):
        load_grid_folder(tmp_path)


def test_grid_yaml_refuses_an_unknown_key_as_a_rig_file_does(tmp_path: Path) -> None:
    """A misspelt key (spacng_y) was silently ignored, the grid then read with spacing_y = spacing_x."""
    from rigctl.errors import RigFileError

    (tmp_path / "grid.yaml").write_text("spacing_x: 0.12\nfocal_px: 100\nspacng_y: 0.078\n")
    with pytest.raises(RigFileError) as info:
        load_grid_folder(tmp_path)
    assert str(info.value) == f"{tmp_path / 'grid.yaml'}:3: spacng_y is not a known field; did you mean 'spacing_y'?"
    (tmp_path / "grid.yaml").write_text("spacing_x: 0.12\nfocal_px: 100\ncolour: red\n")
    with pytest.raises(RigFileError, match=r"grid\.yaml:3: colour is not a known field \(known: spacing_x, "):
        load_grid_folder(tmp_path)


def _png_with(img: np.ndarray, extra: bytes = b"") -> bytes:
    import cv2

    data = cv2.imencode(".png", img)[1].tobytes()
    return data[:33] + extra + data[33:]  # after the signature and IHDR


def _chunk(kind: bytes, body: bytes) -> bytes:
    return len(body).to_bytes(4, "big") + kind + body + zlib.crc32(kind + body).to_bytes(4, "big")


def test_a_damaged_png_is_our_line_and_libpng_says_nothing(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    """libpng printed 'libpng error: IDAT: CRC error' (and warnings for a bad colour profile) on stderr beside our
    'cannot decode' line; chunks are now proven before it decodes, and the ones it does not need left out."""
    img = (np.random.default_rng(0).random((16, 24, 3)) * 255).astype(np.uint8)
    (tmp_path / "grid.yaml").write_text("spacing_x: 1\nfocal_px: 100\n")
    good = _png_with(img)
    damaged = bytearray(good)
    damaged[good.find(b"IDAT") + 8] ^= 0xFF
    for data, says in (
        (bytes(damaged), "r0c0.png: PNG chunk IDAT at byte 33 fails its checksum (damaged)"),
        (good[: len(good) // 2], "r0c0.png: PNG cut short: chunk 'IDAT' at byte 33"),
    ):
        (tmp_path / "r0c0.png").write_bytes(data)
        with pytest.raises(RigctlError, match=re.escape(says)):
            load_grid_folder(tmp_path)
    # a colour profile libpng warns about ("iCCP: too short"): left out, the same pixels, nothing said
    (tmp_path / "r0c0.png").write_bytes(_png_with(img, _chunk(b"iCCP", b"bad\0\0" + zlib.compress(b"x"))))
    grid = load_grid_folder(tmp_path)
    assert np.array_equal(grid.bgr8("r0c0"), img)
    assert "libpng" not in capfd.readouterr().err
