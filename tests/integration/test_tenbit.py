"""10-bit capture end to end (issue 29, part 1), through the installed ``rigctl``: simulated takes recorded
with a rig whose pixel format is Y210 or v210 store 20 bits a pixel, pass ``take check`` and export EXR
whose luma holds 10-bit codes; with ``exposure_stops=1.5`` the EXR keeps highlights above nominal white
where the 8-bit PNG preview clips, in 10 bits and in 8."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from rigctl.capture.preflight import rate_text
from rigctl.exr import linear_to_bt709, read_exr
from rigctl.rig import load_rig
from rigctl.take.reader import TakeReader

_LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)
FRAMES = 2


def _rig(tmp_path: Path, pixel_format: str) -> Path:
    data = load_rig("sim-3x3").to_dict()
    data["format"]["pixel_format"] = pixel_format
    path = tmp_path / f"rig-{pixel_format}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _record_and_export(run_cli, tmp_path: Path, pixel_format: str, *sim: str) -> Path:
    rig = _rig(tmp_path, pixel_format)
    args = [a for s in sim for a in ("--sim", s)]
    r = run_cli("record", str(rig), "--take", "t", "--frames", str(FRAMES), *args, "--out", str(tmp_path), timeout=600)
    assert r.returncode == 0, r.stderr
    # preflight and the report state the data rate a camera and for the array: what reaches the disk
    bits = 20 if pixel_format in ("Y210", "v210") else 16
    camera = 960 * 540 * bits / 8 * 25
    assert f"data rate: {rate_text(camera)} a camera" in r.stderr, r.stderr
    assert f"{rate_text(9 * camera)} for the array" in r.stderr
    assert f"data rate: {rate_text(camera)} a camera, {rate_text(9 * camera)} for the array ({bits} bits" in r.stdout
    take = tmp_path / "t"
    check = run_cli("take", "check", str(take), timeout=300)
    assert check.returncode == 0, check.stdout + check.stderr
    for fmt in ("exr", "png"):
        r = run_cli("take", "export", str(take), "--out", str(tmp_path / fmt), "--format", fmt, "--frames", "0")
        assert r.returncode == 0, r.stderr
    return take


def _pictures(tmp_path: Path, camera: str = "r1c1") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scene-linear RGB (un-premultiplied), its alpha, and the PNG preview (BGR) of one camera."""
    ch, _ = read_exr(tmp_path / "exr" / "000000" / f"{camera}.exr")
    alpha = ch["A"]
    rgb = ch["RGB"] / np.maximum(alpha[..., None], 1e-6)
    png = cv2.imread(str(tmp_path / "png" / "000000" / f"{camera}.png"))
    assert png is not None
    return rgb, alpha, png


def _luma_codes(rgb: np.ndarray) -> np.ndarray:
    """The EXR's light taken back through BT.709's OETF to 10-bit luma codes."""
    return np.rint(64 + 876 * (linear_to_bt709(rgb) @ _LUMA)).astype(np.int64)


@pytest.mark.parametrize("pixel_format", ["Y210", "v210"])
def test_a_ten_bit_take_stores_twenty_bits_a_pixel_and_exports_ten_bit_codes_and_highlights(
    run_cli, tmp_path: Path, pixel_format: str
) -> None:
    take = _record_and_export(run_cli, tmp_path, pixel_format, "deterministic=true", "ideal=true", "exposure_stops=1.5")
    reader = TakeReader(take)
    assert reader.pixel_format == pixel_format
    for name in reader.names:
        essence = take / "cameras" / f"{name}.essence"
        assert essence.stat().st_size * 8 == FRAMES * reader.width * reader.height * 20  # 20 bits a pixel
    rgb, alpha, png = _pictures(tmp_path)
    subject = alpha > 0.99
    codes = _luma_codes(rgb)[subject]
    share = float((codes % 4 != 0).mean())
    # 10-bit data: about three codes in four are not multiples of 4 (measured 0.77); 8-bit data: none
    assert share > 0.6, f"only {share:.2f} of luma codes off multiples of 4"
    saturated = png.max(axis=2) == 255
    assert saturated.sum() > 1000
    above = float((rgb.max(axis=2)[saturated] > 1.05).mean())
    assert above > 0.5, f"only {above:.2f} of the PNG's saturated pixels are above 1.05 in the EXR"
    assert rgb.max() > 1.05 and rgb.min() < 0.0  # super-whites and sub-blacks, not folded


def test_the_eight_bit_path_keeps_its_super_whites_and_stays_eight_bit(run_cli, tmp_path: Path) -> None:
    take = _record_and_export(run_cli, tmp_path, "UYVY", "deterministic=true", "ideal=true", "exposure_stops=1.5")
    assert (take / "cameras" / "r0c0.essence").stat().st_size == FRAMES * 960 * 540 * 2
    rgb, alpha, png = _pictures(tmp_path)
    codes = _luma_codes(rgb)[alpha > 0.99]
    assert (codes % 4 != 0).mean() < 0.02  # 8-bit codes, as before
    saturated = png.max(axis=2) == 255
    assert saturated.sum() > 1000
    assert (rgb.max(axis=2)[saturated] > 1.05).mean() > 0.5


def test_a_ten_bit_take_with_the_simulators_defaults(run_cli, tmp_path: Path) -> None:
    """Live capture, noise, motion, vignetting: the take is whole, 20 bits a pixel, and its codes 10-bit.
    (Live, a busy machine may lose frames at the source, as the 8-bit simulator does; they are counted.)"""
    take = _record_and_export(run_cli, tmp_path, "Y210")
    reader = TakeReader(take)
    stored = 0
    for name, entry in reader.manifest.cameras.items():
        size = (take / "cameras" / f"{name}.essence").stat().st_size
        assert size * 8 == entry.frames * reader.width * reader.height * 20
        stored += entry.frames
    assert stored > 0
    rgb, alpha, _ = _pictures(tmp_path, sorted(reader.frame_sets[0].members)[0])
    assert np.isfinite(rgb).all()
    # noise alone would put codes off multiples of 4; the ideal takes above prove the rendering is 10-bit
    assert (_luma_codes(rgb)[alpha > 0.99] % 4 != 0).mean() > 0.6


def test_bench_record_prints_ten_bit_throughput_beside_eight_bit(run_cli, tmp_path: Path) -> None:
    args = ["bench", "record", "--size", "192x108", "--frames", "4", "--rounds", "1", "--dir", str(tmp_path)]
    r = run_cli(*args, "--json", timeout=600)
    assert r.returncode == 0, r.stderr
    rows = {row["pixel_format"]: row for row in json.loads(r.stdout)}
    assert set(rows) == {"UYVY", "Y210", "v210"}
    for pf, row in rows.items():
        assert row["fps"] > 0 and row["cpu_per_frame_s"] > 0
        assert row["stored_bytes_per_frame"] == 192 * 108 * (20 if pf != "UYVY" else 16) // 8
    assert rows["Y210"]["device_bytes_per_frame"] == 192 * 108 * 4
    text = run_cli(*args, timeout=600)
    assert text.returncode == 0, text.stderr
    lines = text.stdout.splitlines()
    assert any(line.strip().startswith("UYVY  8-bit:") and "GB/s stored" in line for line in lines), text.stdout
    assert any(line.strip().startswith("Y210 10-bit:") and "stored at 20 bits a pixel" in line for line in lines)
    assert any(line.strip().startswith("Y210 / UYVY: frames") for line in lines)
    assert not list(tmp_path.iterdir())  # its takes are removed
