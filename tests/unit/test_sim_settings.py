"""``--sim KEY=VALUE`` settings: parsed, validated, errors name the key."""

from __future__ import annotations

import pytest
from rigctl.simulators.settings import describe_settings, parse_sim_args

from rigctl.errors import ParameterError
from rigctl.registry import open_cameras
from rigctl.rig import load_rig


def test_values_and_per_camera_keys() -> None:
    s = parse_sim_args(
        [
            "ideal=true",
            "seed=7",
            "subject_distance_m=2.4",
            "drops.r0c1=5,6,20",
            "skew_us.r2c2=3000",
            "signal_loss.r1c1=[1.0,1.5]",
        ]
    )
    assert s.ideal and s.seed == 7 and s.subject_distance_m == 2.4
    assert s.drops == {"r0c1": [5, 6, 20]} and s.skew_us == {"r2c2": 3000.0}
    assert s.signal_loss == {"r1c1": (1.0, 1.5)}
    eff = s.effective()
    assert eff.noise == 0 and eff.mount_rotation_deg == 0 and eff.distortion_k1 == 0


@pytest.mark.parametrize(
    ("pairs", "message"),
    [
        (["colour=red"], "--sim colour: unknown setting"),
        (["seed"], "expected KEY=VALUE"),
        (["noise=-1"], "--sim noise: "),
        (["drops.centre=[1]"], "is not a camera name"),
        (["scene=forest"], "--sim scene: "),
        (["subject_distance_m=nan"], "--sim subject_distance_m"),
        (["seed.r0c0=1"], "seed is not a per-camera setting"),
        # absurd but valid numbers, which hung a recording or crashed its writer (a hostile-user review)
        (["seed=-1"], "--sim seed: "),
        (["stagger_ms=1e9"], "--sim stagger_ms: "),
        (['skew_us={"r1c1": 1e13}'], "--sim skew_us.r1c1: "),
        (["skew_us.r1c1=-inf"], "--sim skew_us.r1c1: "),
        (["jitter_us=1e30"], "--sim jitter_us: "),
        (["noise=1e30"], "--sim noise: "),
        (["vignetting=5"], "--sim vignetting: "),
    ],
)
def test_bad_settings_are_named(pairs: list[str], message: str) -> None:
    with pytest.raises(ParameterError, match=message.replace(".", r"\.").replace("[", r"\[")):
        parse_sim_args(pairs)


@pytest.mark.parametrize(
    ("pairs", "message"),
    [
        (["drops.r9c9=[0]"], "--sim drops.r9c9: rig sim-3x3 has no camera r9c9 (its cameras: r0c0, r0c1,"),
        (["skew_us.r3c0=10"], "--sim skew_us.r3c0: rig sim-3x3 has no camera r3c0"),
        (["signal_loss.r0c3=[1,2]"], "--sim signal_loss.r0c3: rig sim-3x3 has no camera r0c3"),
        (["unlocked=[r1c1,r7c7]"], "--sim unlocked=r7c7: rig sim-3x3 has no camera r7c7"),
    ],
)
def test_a_fault_for_a_camera_the_rig_lacks_is_refused(pairs: list[str], message: str) -> None:
    """A hostile-user review: ``drops.r9c9=[0]`` on a 3x3 rig was accepted and injected nothing."""
    rig = load_rig("sim-3x3")
    assert parse_sim_args(pairs).model_dump()  # a valid camera name: the settings alone cannot tell
    with pytest.raises(ParameterError) as caught:
        parse_sim_args(pairs, rig=rig)
    assert message in str(caught.value) and str(caught.value).endswith("r2c2)")
    with pytest.raises(ParameterError, match="no camera r9c9"):
        open_cameras(rig, ["drops.r9c9=[0]"])  # where record, the shoot UI and the demo get their cameras


def test_help_lists_every_setting() -> None:
    text = describe_settings()
    for key in ("scene=", "seed=", "ideal=", "drops=", "skew_us=", "signal_loss=", "stagger_ms=", "jitter_us="):
        assert key in text


def test_deterministic_capture_needs_every_camera_simulated() -> None:
    from rigctl.errors import DeviceError
    from rigctl.registry import open_cameras
    from rigctl.rig import load_rig, rig_from_dict

    data = load_rig("sim-3x3").to_dict()
    data["cameras"][0]["device"] = "v4l2:///dev/video0"
    rig = rig_from_dict(data)
    assert not open_cameras(rig, ["motion=false"]).paced
    with pytest.raises(DeviceError, match=r"deterministic=true: rig \S+ has cameras that are not simulated"):
        open_cameras(rig, ["deterministic=true", "motion=false"])
    assert open_cameras(load_rig("sim-3x3"), ["deterministic=true", "motion=false"]).paced
