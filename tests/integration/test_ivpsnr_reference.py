"""Our IV-PSNR against the metric's authors' reference software (built from source by
shared/tools/build-ivpsnr), on their published pictures and on constructed ones at 10 bits."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import SHARED
from interop_support import reference_tool

from rigctl.interop import yuv
from rigctl.interop.ivpsnr import ivpsnr, upsample_420

EXAMPLE = SHARED / "tools" / "ivpsnr" / "example"
W, H = 1920, 1080
# the README of the authors' example: (test picture, mask or None) -> (PSNR-Y, IV-PSNR) in dB
PUBLISHED = {
    ("synthesized", None): (34.0128, 44.3555),
    ("origJpgCompressed", None): (34.3362, 39.1335),
    ("synthesized", "objectsMask"): (39.5414, 50.7716),
}


def example(name: str) -> Path:
    path = EXAMPLE / f"Fencing_v8_{name}_1920x1080_yuv420p.yuv"
    assert path.is_file(), f"{path} is missing (the authors' example pictures, in shared/tools/ivpsnr/example)"
    return path


def reference_ivpsnr(ref: Path, test: Path, size: tuple[int, int], pix_fmt: str, mask: Path | None) -> float:
    argv = [str(reference_tool("ivpsnr")), "-i0", str(ref), "-i1", str(test), "-ps", f"{size[0]}x{size[1]}",
            "-pf", pix_fmt, "-ml", "PSNR, IVPSNR"] + (["-im", str(mask), "-bdm", "8"] if mask else [])  # fmt: skip
    out = subprocess.run(argv, capture_output=True, text=True, timeout=120, check=True).stdout
    m = re.search(r"Average\s+IVPSNR(?:-M)?\s+([0-9.]+) dB", out)
    assert m is not None, out
    return float(m[1])


def load(path: Path, w: int = W, h: int = H, bits: int = 8) -> np.ndarray:
    return upsample_420(*yuv.read_frame(path, w, h, bits))  # type: ignore[arg-type]


@pytest.mark.parametrize(("test", "mask"), list(PUBLISHED))
def test_ours_matches_the_reference_on_the_published_pictures(test: str, mask: str | None) -> None:
    psnr_y, published = PUBLISHED[(test, mask)]
    m = None if mask is None else load(example(mask))[0]
    ours = ivpsnr(load(example("original")), load(example(test)), 8, m, mask_bit_depth=8)
    theirs = reference_ivpsnr(example("original"), example(test), (W, H), "yuv420p", example(mask) if mask else None)
    assert theirs == pytest.approx(published, abs=5e-5)  # the binary reproduces its README
    assert ours.ivpsnr_db == pytest.approx(theirs, abs=2e-6)  # it prints 6 decimals
    assert ours.psnr_db[0] == pytest.approx(psnr_y, abs=5e-5)


def test_ours_matches_the_reference_on_shifted_offset_noisy_10_bit_pictures(tmp_path: Path) -> None:
    """Smooth texture, shifted by 1 px right and 2 px down in one half and 3 px in the other (beyond the
    search), a colour offset beyond the unnoticeable one in Y and within it in Cr, and noise: ties between
    equal candidates, clipping of the offset and edge repetition all matter here."""
    w, h, bits = 160, 96, 10
    rng = np.random.default_rng(7)
    yy, xx = np.mgrid[0:h, 0:w]
    ref = np.stack([512 + 300 * np.sin(xx / 7.0) * np.cos(yy / 5.0), 512 + 100 * np.sin(yy / 9.0),
                    512 + 80 * np.cos(xx / 11.0)]).round()  # fmt: skip
    ref += rng.integers(-3, 4, ref.shape)
    test = ref.copy()
    test[:, 2:, 1:] = ref[:, :-2, :-1]
    test[:, :, w // 2 + 3 :] = ref[:, :, w // 2 : -3]
    test += np.array([14, 0, -4])[:, None, None] + rng.integers(-2, 3, ref.shape)
    files = {}
    for name, pic in (("ref", ref), ("test", test)):
        pic = np.clip(pic, 0, 1023).astype(np.uint16)
        planes = [pic[0], yuv.subsample_420(pic[1]), yuv.subsample_420(pic[2])]
        files[name] = tmp_path / f"{name}.yuv"
        with open(files[name], "wb") as f:
            yuv.write_frame(f, planes, bits)
    mask = np.zeros((h, w), np.uint8)
    mask[10:70, 20:150] = 255
    files["mask"] = tmp_path / "mask.yuv"
    with open(files["mask"], "wb") as f:
        yuv.write_frame(f, [mask, np.zeros((h // 2, w // 2), np.uint8), np.zeros((h // 2, w // 2), np.uint8)], 8)
    for m in (None, mask):
        ours = ivpsnr(load(files["ref"], w, h, bits), load(files["test"], w, h, bits), bits, m, mask_bit_depth=8)
        theirs = reference_ivpsnr(
            files["ref"], files["test"], (w, h), "yuv420p10le", files["mask"] if m is not None else None
        )
        assert ours.ivpsnr_db == pytest.approx(theirs, abs=2e-6), m is None
        assert ours.offset[0] == 10  # clipped to round(0.01 * 1023)


def test_the_cli_reads_raw_yuv_and_refuses_a_wrong_size_in_one_line(run_cli) -> None:
    r = run_cli("miv", "ivpsnr", str(example("original")), str(example("origJpgCompressed")), "--size", "1920x1080")
    assert r.returncode == 0, r.stderr
    assert "IV-PSNR 39.1335 dB" in r.stdout
    bad = run_cli("miv", "ivpsnr", str(example("original")), str(example("synthesized")), "--size", "1000x1000")
    assert bad.returncode == 3
    assert bad.stderr.count("\n") == 1 and "1000x1000" in bad.stderr, bad.stderr
