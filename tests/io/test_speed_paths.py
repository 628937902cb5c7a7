"""The fast paths give what the plain ones give.

- The DMIS reader's fast lane and the CSV reader's typed parse: the same records
  (or the same error) as the general readers, on canonical files, on files that
  take the general route in places, and on fuzzed files.
- The vectorized computations (sphere fits, registration, FGM, the whole
  process) against the straightforward reference of ``bench/straightforward.py``
  (one scipy solve per sphere and per pose), on a few spheres and poses.

No timing here: ``bench/speed.py`` measures.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hexatherm.core.geometry import rotation_derivatives
from hexatherm.errors import InputError
from hexatherm.io import csvfile, dmis, measurements
from hexatherm.io.records import Records
from tests.conftest import make_hexapod, random_poses
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]


def _straightforward():
    spec = importlib.util.spec_from_file_location(
        "straightforward", ROOT / "bench" / "straightforward.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["straightforward"] = module
    spec.loader.exec_module(module)
    return module


# ----------------------------------------------------------------------------- helpers
def assert_same_records(got: list[Records], want: list[Records]) -> None:
    assert len(got) == len(want)
    for a, b in zip(got, want, strict=True):
        assert (a.path, a.kind, a.time_kind) == (b.path, b.kind, b.time_kind)
        for name in ("label", "ball", "xyz_mm", "time_s", "line", "diameter_mm", "ijk"):
            x, y = getattr(a, name), getattr(b, name)
            assert (x is None) == (y is None), name
            if x is not None:
                assert x.dtype == y.dtype, (name, x.dtype, y.dtype)
                assert x.shape == y.shape, name
                assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name
        assert a.extra.keys() == b.extra.keys()
        for key in a.extra:
            x, y = np.asarray(a.extra[key]), np.asarray(b.extra[key])
            assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), key


def outcome(read, *args):
    """The records a reader returns, or the text of the InputError it raises."""
    try:
        return read(*args)
    except InputError as error:
        return f"InputError: {error}"


def assert_same_outcome(got, want) -> None:
    if isinstance(want, str) or isinstance(got, str):
        assert got == want
    else:
        assert_same_records(got, want)


# ----------------------------------------------------------------------------- DMIS
def general_dmis(path: Path) -> list[Records]:
    return dmis.records_from_features(dmis.features_from_text(dmis._read_text(path), path), path)


def check_dmis(path: Path, fast: bool | None = None) -> None:
    """read_dmis == the general reader; ``fast``: whether the fast lane must (not) read it."""
    assert_same_outcome(outcome(dmis.read_dmis, path), outcome(general_dmis, path))
    if fast is not None:
        assert (dmis._fast_records(path.read_bytes(), path) is not None) == fast


def points_dmo(
    n_steps: int = 3, balls: int = 2, points: int = 5, ijk: bool = True, seed: int = 0
) -> str:
    rng = np.random.default_rng(seed)
    lines = ["DMISMN/'hexatherm twin output',04.0", "UNITS/MM,ANGDEC", "FILNAM/'x'"]
    second = 0
    for step in range(n_steps):
        for ball in range(1, balls + 1):
            for k in range(1, points + 1):
                second += 2
                lines += ["DATE=2024/03/05", f"TIME=07:{second // 60 % 60:02d}:{second % 60:02d}"]
                xyz = ",".join(repr(float(v)) for v in rng.normal(100, 50, 3))
                tail = "," + ",".join(repr(float(v)) for v in rng.normal(size=3)) if ijk else ""
                label = "O" if step == 0 else f"S{step}"
                lines += [
                    f"FA({label}_B{ball}_{k})=FEAT/POINT,CART,{xyz}{tail}",
                    f"OUTPUT/FA({label}_B{ball}_{k})",
                ]
    return "\r\n".join(lines + ["ENDFIL"]) + "\r\n"


def write(tmp_path: Path, text: str | bytes, name: str = "run.dmo") -> Path:
    path = tmp_path / name
    path.write_bytes(text.encode("utf-8") if isinstance(text, str) else text)
    return path


@pytest.mark.parametrize("ijk", [True, False])
def test_dmis_canonical_points_take_the_fast_lane(tmp_path, ijk):
    check_dmis(write(tmp_path, points_dmo(ijk=ijk)), fast=True)
    check_dmis(write(tmp_path, points_dmo(ijk=ijk).replace("\r\n", "\n")), fast=True)
    check_dmis(write(tmp_path, "\ufeff" + points_dmo(ijk=ijk)), fast=True)


def test_dmis_twin_session_file_takes_the_fast_lane():
    check_dmis(SHIPPED / "paper-zero-pose-dmis" / "points.dmo", fast=True)


CANONICAL = points_dmo(n_steps=2, balls=2, points=4)


@pytest.mark.parametrize(
    ("old", "new"),
    [
        # read in place, one by one or as arrays: same records
        ("UNITS/MM,ANGDEC", "UNITS/INCH,ANGDEC"),
        ("FA(O_B1_2)", "DATE=2024/03/06\r\nUNITS/CM\r\nFA(O_B1_2)"),
        (
            "FA(O_B1_1)",
            "F(O_B1_1)=FEAT/POINT,CART,0,0,0\r\nT(X)=TOL/CORTOL,XAXIS,-1,1\r\nFA(O_B1_1)",
        ),
        ("FA(O_B1_1)", "FA(CIRC)=FEAT/CIRCLE,INNER,CART,1,2,3,0,0,1,15\r\nFA(O_B1_1)"),
        ("FA(O_B1_1)", "FA(O_B1)=FEAT/SPHERE,OUTER,CART,1,2,3,25.4\r\nFA(O_B1_1)"),
        ("FA(O_B1_1)", "FA(O_B1)=FEAT/SPHERE,CART,1,2,3,25.4\r\nFA(O_B1_1)"),
        ("FA(O_B1_1)", "  FA(O_B1_1)"),
        (
            "FA(O_B1_1)",
            "FA(O_B2)=FEAT/SPHERE,CART,1,2,3,25.4\r\n FA(O_B1)=FEAT/SPHERE,CART,"
            "4,5,6,25.4\r\nFA(O_B3)=FEAT/SPHERE,CART,7,8,9,25.4\r\nFA(O_B1_1)",
        ),
        ("FA(O_B1_1)", "fa(O_B1_1)"),
        ("FA(O_B1_1)=FEAT/POINT", "FA( O_B1_1 ) = FEAT / point"),
        ("FA(O_B1_2)=FEAT/POINT,CART,", "FA(O_B1_2)=FEAT/POINT,POL,"),
        ("DATE=2024/03/05\r\nTIME=07:00:02", "date = '2024-03-05'\r\nTime=7:00:02.25"),
        ("TIME=07:00:04", "TIME=7:00"),
        ("TIME=07:00:04", "TIME=07:00:04 "),
        ("TIME=07:00:04", "\tTIME=07:00:04"),
        ("ENDFIL", "ENDFIL\r\n\r\n   \r\n"),
        ("-", " -"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1.5E-3,+2.,-.5e+2\r\nFA(X_Y_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,2,3,,,\r\nFA(X_Y_1)"),
        ("FA(S1_B2_4)", "FA(S1-a_B2-b_4x)"),
        # refused: the same error
        ("TIME=07:00:04", "TIME=24:00:04"),
        ("TIME=07:00:04", "TIME=07:60:04"),
        ("DATE=2024/03/05\r\nTIME=07:00:06", "DATE=2024/02/30\r\nTIME=07:00:06"),
        (
            "DMISMN/'hexatherm twin output',04.0\r\nUNITS/MM,ANGDEC\r\nFILNAM/'x'\r\n"
            "DATE=2024/03/05\r\nTIME=07:00:02\r\n",
            "",
        ),
        ("FA(O_B1_1)", "FA(O_B1)"),
        ("FA(O_B1_1)", "FA(O__B1_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1_)"),
        ("FA(O_B1_1)", "FA(_O_B1_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1_2)"),
        ("FA(O_B1_1)", "FA()"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,2,3,4,5,6,7\r\nFA(X_Y_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,2,3,4\r\nFA(X_Y_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,2,3,4,,6\r\nFA(X_Y_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,2,3,\r\nFA(X_Y_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,,3\r\nFA(X_Y_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,2\r\nFA(X_Y_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,2,3,nan,nan,nan\r\nFA(X_Y_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,2,inf\r\nFA(X_Y_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,2,1e999\r\nFA(X_Y_1)"),
        ("FA(O_B1_1)", 'FA(O_B1_1)=FEAT/POINT,CART,1,2,"3"\r\nFA(X_Y_1)'),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,2,3 4\r\nFA(X_Y_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,2,1e\r\nFA(X_Y_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,2,+\r\nFA(X_Y_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,2,1.5.5\r\nFA(X_Y_1)"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1,2,3e400\r\nFA(X_Y_1)"),
        ("UNITS/MM,ANGDEC", "UNITS/FURLONG"),
        ("FA(O_B1_1)", "FA(O_B1_1)=FEAT/POINT,CART,1e308,1,1\r\nUNITS/INCH\r\nFA(O_B1_2)"),
        ("FA(O_B1_1)", "UNITS/INCH\r\nFA(O_B1_1)=FEAT/POINT,CART,1e308,1,1\r\nFA(X_Y_1)"),
        # the general route for the whole file
        ("OUTPUT/FA(O_B1_1)", "OUTPUT/FA(O_B1_1) $$ a comment"),
        ("OUTPUT/FA(O_B1_1)", "OUTPUT/FA($\r\nO_B1_1)"),
        ("OUTPUT/FA(O_B1_1)", "OUTPUT/FA(O_B1_1)\r\n,T(X)"),
        ("OUTPUT/FA(O_B1_1)", "OUTPUT/FA(O_B1_1)\rX"),
    ],
)
def test_dmis_variants_read_as_the_general_reader(tmp_path, old, new):
    assert old in CANONICAL
    check_dmis(write(tmp_path, CANONICAL.replace(old, new, 1)))


def test_dmis_empty_and_blank_files(tmp_path):
    for text in ("", "\r\n", "   \n\n", "\ufeff", "ENDFIL\n", "DATE=2024/03/05\n"):
        check_dmis(write(tmp_path, text))


_TOKENS = [
    b"$",
    b"$$",
    b",",
    b"\r\n",
    b"\n",
    b"\r",
    b" ",
    b"\t",
    b"'",
    b'"',
    b"(",
    b")",
    b"_",
    b"-",
    b"e",
    b"E",
    b"+",
    b".",
    b"0",
    b"9",
    b"FA(",
    b"FA(S9_B9_9)=FEAT/POINT,CART,",
    b"=FEAT/POINT,CART,",
    b"=FEAT/SPHERE,CART,",
    b"POL,",
    b"UNITS/INCH\n",
    b"DATE=2024/02/29\n",
    b"TIME=12:00:00\n",
    b"TIME=",
    b"DATE=",
    b"1e999",
    b"nan",
    b"\xc3\xa9",
    b"\xe2\x80\xa8",
    b"\x0b",
    b"\x1c",
]


@st.composite
def mutated_dmis(draw: st.DrawFn) -> bytes:
    data = bytearray(
        points_dmo(
            n_steps=2, balls=2, points=3, ijk=draw(st.booleans()), seed=draw(st.integers(0, 3))
        ).encode()
    )
    for _ in range(draw(st.integers(min_value=1, max_value=5))):
        at = draw(st.integers(min_value=0, max_value=len(data)))
        operation = draw(st.sampled_from(["delete", "insert", "token", "replace", "copy"]))
        if operation == "delete":
            del data[at : at + draw(st.integers(min_value=1, max_value=30))]
        elif operation == "insert":
            data[at:at] = draw(st.binary(min_size=1, max_size=8))
        elif operation == "token":
            data[at:at] = draw(st.sampled_from(_TOKENS))
        elif operation == "replace" and at < len(data):
            data[at] = draw(st.integers(min_value=0, max_value=127))
        elif operation == "copy":
            size = draw(st.integers(min_value=1, max_value=120))
            data[at:at] = data[max(0, at - size) : at]
    return bytes(data)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=mutated_dmis())
def test_dmis_fuzz_fast_lane_equals_general_reader(tmp_path_factory, data):
    path = tmp_path_factory.getbasetemp() / "fuzz-fast.dmo"
    path.write_bytes(data)
    check_dmis(path)


# ----------------------------------------------------------------------------- sphere fits etc.
def test_sphere_fits_agree_with_one_least_squares_per_sphere():
    sf = _straightforward()
    from hexatherm.core.spherefit import fit_spheres

    rng = np.random.default_rng(3)
    groups, pts = [], []
    for k in range(6):
        z = rng.uniform(np.cos(np.radians(70)), 1.0, 25)
        phi = rng.uniform(0, 2 * np.pi, 25)
        u = np.c_[np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z]
        centre, radius = rng.uniform(-500, 500, 3), rng.uniform(5, 20)
        pts.append(centre + (radius + rng.normal(0, 1e-3, 25))[:, None] * u)
        groups += [k] * 25
    fits = fit_spheres(np.vstack(pts), np.array(groups))
    for k, points in enumerate(pts):
        centre, radius, u_um = sf.fit_sphere(points)
        np.testing.assert_allclose(centre, fits.centre_mm[k], atol=1e-9, rtol=0)
        assert abs(radius - fits.radius_mm[k]) < 1e-9
        assert abs(u_um - np.sqrt(np.trace(fits.cov_centre_mm2[k]) / 3) * 1e3) < 1e-6


def test_registration_agrees_with_align_vectors():
    sf = _straightforward()
    from hexatherm.core.geometry import apply_transform, transform_from_pose
    from hexatherm.core.registration import register

    rng = np.random.default_rng(4)
    balls = np.array([[0.0, 90, 30], [-73.6, -42.5, 30], [82.3, -47.5, 30], [10, 10, 60]])
    frames = transform_from_pose(random_poses(rng, 5) + [400, 300, 200, 0, 0, 15])
    centres = apply_transform(frames, balls) + rng.normal(0, 2e-3, (5, 4, 3))
    weights = rng.uniform(0.5, 2.0, (5, 4))
    fit = register(centres, balls, weights)
    for i in range(5):
        np.testing.assert_allclose(
            sf.register_step(centres[i], balls, weights[i]), fit.platform2cmm[i], atol=1e-10, rtol=0
        )


def test_registration_rotations_agree_with_the_svd():
    """Horn's quaternion form gives Kabsch's rotations, also for large rotations, heavy
    noise and lopsided weights (there by falling back on the SVD)."""
    from hexatherm.core.geometry import apply_transform, transform_from_pose
    from hexatherm.core.registration import _kabsch, _rotations

    rng = np.random.default_rng(8)
    balls = np.array([[0.0, 90, 30], [-73.6, -42.5, 30], [82.3, -47.5, 30]])
    n = 3000
    poses = rng.uniform(-1, 1, (n, 6)) * [20, 20, 15, 180, 89, 180] + [450, 320, 210, 0, 0, 15]
    frames = transform_from_pose(poses)
    for noise in (0.0, 1e-3, 5.0):
        centres = apply_transform(frames, balls) + rng.normal(0, noise, (n, 3, 3))
        w = 10 ** rng.uniform(-6, 0, (n, 3))
        w /= w.sum(axis=1, keepdims=True)
        b = balls[None] - (w @ balls)[:, None]
        c = centres - np.einsum("nk,nki->ni", w, centres)[:, None]
        cov = np.einsum("nk,nki,nkj->nij", w, c, b)
        scale = 0.5 * (np.einsum("nk,nki,nki->n", w, b, b) + np.einsum("nk,nki,nki->n", w, c, c))
        np.testing.assert_allclose(_rotations(cov, scale), _kabsch(cov), atol=1e-12, rtol=0)
        if noise == 0.0:
            np.testing.assert_allclose(_rotations(cov, scale), frames[:, :3, :3], atol=1e-9)


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_fgm_agrees_with_one_root_per_pose(convention):
    sf = _straightforward()
    hexapod = make_hexapod(convention)
    rng = np.random.default_rng(5)
    poses = random_poses(rng, 8)
    q = hexapod.igm(poses)
    starts = poses + rng.normal(0, 0.05, poses.shape)
    got = hexapod.fgm(q, initial_poses=starts)
    for i in range(len(poses)):
        np.testing.assert_allclose(sf.fgm_pose(hexapod, q[i], starts[i]), got[i], atol=1e-9, rtol=0)
    np.testing.assert_allclose(got, poses, atol=1e-9, rtol=0)
    # and its IGM agrees with the one-pose IGM of scipy's rotations
    for i in range(len(poses)):
        np.testing.assert_allclose(sf.leg_lengths(poses[i], hexapod), q[i], atol=1e-11, rtol=0)


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_jacobian_agrees_with_the_rotation_derivatives(convention):
    hexapod = make_hexapod(convention)
    poses = random_poses(np.random.default_rng(6), 50, scale=4.0)
    legs = hexapod.leg_vectors(poses)
    units = legs / np.linalg.norm(legs, axis=-1, keepdims=True)
    d_plat = np.einsum(
        "nkij,lj->nlki", rotation_derivatives(poses[:, 3:], convention), hexapod.platform_joints_mm
    )
    jac = hexapod.jacobian(poses)
    np.testing.assert_allclose(jac[:, :, :3], units, atol=1e-15, rtol=0)
    np.testing.assert_allclose(
        jac[:, :, 3:], np.einsum("nli,nlki->nlk", units, d_plat), atol=1e-13, rtol=0
    )


def test_fgm_conditioning_bound_matches_the_svd():
    """Where the cheap bound says 'surely regular' the SVD agrees; near-singular poses
    are found, with the same reciprocal condition as an SVD."""
    hexapod = make_hexapod()
    jac = hexapod.jacobian(random_poses(np.random.default_rng(7), 200))
    rcond, low, _ = hexapod._conditioning(jac, None, np.full(200, np.nan))
    sv = np.linalg.svd(jac, compute_uv=False)
    assert np.all(low <= sv[:, -1] * (1 + 1e-12))
    assert np.all(np.isinf(rcond))  # a realistic workspace: all surely regular
    near = jac.copy()
    near[:, :, 5] = near[:, :, 4] * (1 + 1e-12)  # two columns (nearly) the same
    rcond, _, _ = hexapod._conditioning(near, jac, low)
    sv = np.linalg.svd(near, compute_uv=False)
    np.testing.assert_allclose(rcond, sv[:, -1] / sv[:, 0], rtol=1e-12, atol=0)


# ----------------------------------------------------------------------------- whole process
@pytest.mark.parametrize(("output", "log"), [("points", True), ("dmis", True), ("points", False)])
def test_process_agrees_with_the_straightforward_way(tmp_path, output, log):
    """Every step of process against the plain one, O carried to R0's thermal state
    (issue 35) by the log and the leg model, or without a log by the references."""
    from hexatherm.workflows.process.pipeline import process_session
    from tests.sessions import make_session

    sf = _straightforward()
    make_session(tmp_path / "s", n_targets=4, output=output, point_noise_mm=1e-3)
    if not log:
        yaml = tmp_path / "s" / "session.yaml"
        text = yaml.read_text()
        assert "temperatures:" in text
        yaml.write_text(
            "".join(line for line in text.splitlines(True) if "temperatures" not in line)
        )
    ours = process_session(tmp_path / "s")
    assert ours.carry is not None and ours.carry.source == ("log" if log else "references")
    plain = sf.process(tmp_path / "s")
    np.testing.assert_allclose(plain["centres_mm"], ours.centres.centres_mm, atol=1e-9, rtol=0)
    np.testing.assert_allclose(plain["times_s"], ours.centres.times_s, atol=1e-6, rtol=0)
    np.testing.assert_allclose(
        plain["platform2cmm"], ours.registration.platform2cmm, atol=1e-9, rtol=0
    )
    np.testing.assert_allclose(
        plain["conventional"], ours.correction.conventional, atol=1e-9, rtol=0
    )
    np.testing.assert_allclose(plain["corrected"], ours.correction.corrected, atol=1e-9, rtol=0)


# ----------------------------------------------------------------------------- CSV
def general_csv(path: Path, kind=None) -> list[Records]:
    fast = csvfile._fast_measurement_csv
    csvfile._fast_measurement_csv = lambda *args: None
    try:
        return [csvfile.read_measurement_csv(path, kind)]
    finally:
        csvfile._fast_measurement_csv = fast


def check_csv(path: Path, fast: bool | None = None, kind=None) -> None:
    assert_same_outcome(
        outcome(lambda p: [csvfile.read_measurement_csv(p, kind)], path),
        outcome(general_csv, path, kind),
    )
    if fast is not None:
        used = csvfile._fast_measurement_csv(path.read_bytes(), str(path), kind)
        assert (used is not None) == fast


def points_csv(seconds: bool = False, ijk: bool = True, seed: int = 0) -> str:
    rng = np.random.default_rng(seed)
    lines = ["label,ball,x,y,z,time" + (",i,j,k" if ijk else "")]
    for step in ("O", "R0", "S1"):
        for ball in ("B1", "B2"):
            for _ in range(4):
                t = f"{len(lines) * 2.5:.1f}" if seconds else f"2024-03-05T07:30:{len(lines):02d}"
                row = [step, ball, *(repr(float(v)) for v in rng.normal(100, 50, 3)), t]
                if ijk:
                    row += [repr(float(v)) for v in rng.normal(size=3)]
                lines.append(",".join(row))
    return "\n".join(lines) + "\n"


def centres_csv() -> str:
    return (
        "label,ball,x,y,z,time,diameter,form_um,n,u_um\n"
        "O,B1,1.5,2.5,3.5,2024-03-05T07:30:00,25.4,1.2,25,0.3\n"
        "O,B2,4.5,5.5,6.5,2024-03-05T07:30:10,25.4,1.1,25,0.2\n"
        "R0,B1,7.5,8.5,9.5,2024-03-05T07:31:00,25.4,1.0,25,0.25\n"
    )


@pytest.mark.parametrize("seconds", [False, True])
@pytest.mark.parametrize("ijk", [True, False])
@pytest.mark.parametrize("chunk_rows", [None, 1])
def test_csv_clean_files_take_the_fast_path(tmp_path, seconds, ijk, chunk_rows, monkeypatch):
    if chunk_rows is not None:  # in chunks of one row, the fast path still reads them
        monkeypatch.setattr(csvfile, "CHUNK_ROWS", chunk_rows)
    check_csv(write(tmp_path, points_csv(seconds, ijk), "points.csv"), fast=True)
    check_csv(
        write(tmp_path, points_csv(seconds, ijk).replace("\n", "\r\n"), "points.csv"), fast=True
    )
    check_csv(write(tmp_path, centres_csv(), "centres.csv"), fast=True)
    check_csv(write(tmp_path, centres_csv(), "centres.csv"), fast=True, kind="centres")


CLEAN = points_csv()


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("O,B1,", " O , B1 ,"),
        ("O,B1,", "O,B1, "),
        (",i,j,k\n", ", i ,j,k\n"),
        ("\nO,B1,", "\n\nO,B1,"),
        ("\nS1,B2,", "\n,,,,,,,,\nS1,B2,"),
        ("\nO,B1,", '\n"O",B1,'),
        ("2024-03-05T07:30:03", "2024-03-05T07:30:03 "),
        ("2024-03-05T07:30:03", "12.5"),
        ("2024-03-05T07:30:03", ""),
        ("2024-03-05T07:30:03", "yesterday"),
        ("2024-03-05T07:30:03", "2024-03-05T07:30:03+01:00"),
        ("O,B1,", "O_1,B1,"),
        ("O,B1,", "O,B 1,"),
        ("O,B1,", ",B1,"),
        ("\nO,B1,", "\nO,B1,nan,"),
        ("\nO,B1,", "\nO,B1,1e999,"),
        ("\nO,B1,", "\nO,B1,inf,"),
        ("\nO,B1,", "\nO,B1,,"),
        ("\nO,B1,", "\nO,B1,0x10,"),
        ("\nO,B1,", "\nO,B1,1_0,"),
        (",i,j,k\n", ",i,j,k,diameter\n"),
        (",i,j,k\n", ",i,j\n"),
        (",i,j,k\n", ",i,j,k,extra\n"),
        (",i,j,k\n", ",i,j,i\n"),
        ("label,ball", "Label,ball"),
    ],
)
@pytest.mark.parametrize("chunk_rows", [None, 1, 2])
def test_csv_variants_read_as_the_general_reader(tmp_path, old, new, chunk_rows, monkeypatch):
    assert old in CLEAN
    if chunk_rows is not None:  # a scanning probe's file is read in chunks (issue 37)
        monkeypatch.setattr(csvfile, "CHUNK_ROWS", chunk_rows)
    check_csv(write(tmp_path, CLEAN.replace(old, new, 1), "points.csv"))


@pytest.mark.parametrize(
    "text",
    [
        "",
        "label,ball,x,y,z,time\n",
        "label,ball,x,y,z,time\nO,B1,1,2,3,0\n",
        "label,ball,x,y,z,time\nO,B1,1,2,3,0\nO,B1,1,2,3,1\n",
        "label,ball,x,y,z,time,diameter\nO,B1,1,2,3,0,\nO,B1,1,2,3,1,25\n",
        "label,ball,x,y,z,time,diameter\nO,B1,1,2,3,0,nan\n",
        "label,ball,x,y,z,time,n\nO,B1,1,2,3,0,1e999\n",
        "label,ball,x,y,z,time,i,j,k\nO,B1,1,2,3,0,,,\nO,B1,1,2,3,1,1,0,0\n",
        "label,ball,x,y,z,time,i,j,k\nO,B1,1,2,3,0,nan,nan,nan\n",
        "label,ball,x,y,z,time,i,j,k\nO,B1,1,2,3,0,1,0\n",
        "label,ball,x,y,z,time,i,j,k\nO,B1,1,2,3,0,1,0,0,9\n",
        "label,ball,x,y,z,time\nO,B1,1,2,3,2024-01-01T00:00:00\nO,B2,1,2,3,5\n",
    ],
)
@pytest.mark.parametrize("name", ["points.csv", "centres.csv", "data.csv"])
@pytest.mark.parametrize("chunk_rows", [None, 1])
def test_csv_small_files_read_as_the_general_reader(tmp_path, text, name, chunk_rows, monkeypatch):
    if chunk_rows is not None:
        monkeypatch.setattr(csvfile, "CHUNK_ROWS", chunk_rows)
    check_csv(write(tmp_path, text, name))


_CSV_TOKENS = [
    b",",
    b"\n",
    b"\r\n",
    b"\r",
    b" ",
    b"\t",
    b'"',
    b"'",
    b"nan",
    b"inf",
    b"1e999",
    b"-",
    b"+",
    b".",
    b"e",
    b"_",
    b"T",
    b":",
    b"0",
    b"label",
    b",i,j,k",
    b"\xc2\xa0",
]


@st.composite
def mutated_csv(draw: st.DrawFn) -> bytes:
    data = bytearray(
        points_csv(
            seconds=draw(st.booleans()), ijk=draw(st.booleans()), seed=draw(st.integers(0, 3))
        ).encode()
    )
    for _ in range(draw(st.integers(min_value=1, max_value=4))):
        at = draw(st.integers(min_value=0, max_value=len(data)))
        operation = draw(st.sampled_from(["delete", "token", "replace", "copy"]))
        if operation == "delete":
            del data[at : at + draw(st.integers(min_value=1, max_value=20))]
        elif operation == "token":
            data[at:at] = draw(st.sampled_from(_CSV_TOKENS))
        elif operation == "replace" and at < len(data):
            data[at] = draw(st.integers(min_value=32, max_value=126))
        elif operation == "copy":
            size = draw(st.integers(min_value=1, max_value=80))
            data[at:at] = data[max(0, at - size) : at]
    return bytes(data)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=mutated_csv(), name=st.sampled_from(["points.csv", "m.csv"]))
def test_csv_fuzz_fast_path_equals_general_reader(tmp_path_factory, data, name):
    path = tmp_path_factory.getbasetemp() / name
    path.write_bytes(data)
    check_csv(path)


def test_progress_callbacks_report_lines(tmp_path, monkeypatch):
    """The DMIS reader reports its progress: now and then on the general path, once on the
    fast lane; a CSV file reports once."""
    monkeypatch.setattr(dmis, "_PROGRESS_EVERY", 1000)
    calls: list[tuple[int, int]] = []
    text = points_dmo(n_steps=30, balls=3, points=25)
    slow = write(tmp_path, text.replace("OUTPUT/", "$$ a comment\r\nOUTPUT/"), "slow.dmo")
    fast = write(tmp_path, text, "fast.dmo")
    measurements.read_measurements(slow, progress=lambda done, total: calls.append((done, total)))
    lines = slow.read_text().count("\n")
    assert len(calls) > 2 and calls[-1][0] == calls[-1][1] and calls[-1][1] >= lines - 2
    assert [done for done, _ in calls] == sorted(done for done, _ in calls)
    calls.clear()
    measurements.read_measurements(fast, progress=lambda done, total: calls.append((done, total)))
    assert len(calls) == 1 and calls[0][0] == calls[0][1]
    calls.clear()
    points = write(tmp_path, points_csv(), "points.csv")
    measurements.read_measurements(points, progress=lambda done, total: calls.append((done, total)))
    assert calls == [(25, 25)]


def test_a_plus_sign_reads_as_the_fast_reader_and_float_read_it(tmp_path):
    # issue 37 (io10k; found by the fuzz test above): pd.to_numeric read
    # "+113.63956695822269" one step off (…267), where pandas' C parser (the fast reader)
    # and float read …269: the general reader (a quote, a BOM, a CR sends a file there)
    # now takes the sign off first; a '+' before no digit stays refused
    rng = np.random.default_rng(37)
    texts = [repr(float(v)) for v in rng.normal(100, 50, 3 * 300)]
    signed = ["+" + t if not t.startswith("-") else t for t in texts]
    rows = [
        ",".join(
            [("O", "R0", "S1")[i // 100], ("B1", "B2")[i // 50 % 2], *signed[3 * i : 3 * i + 3]]
        )
        + f",{i}.5"
        for i in range(300)
    ]
    body = "label,ball,x,y,z,time\n" + "\n".join(rows) + "\n"
    path = tmp_path / "points.csv"
    for text in (body, "\ufeff" + body, body.replace("\n", "\r\n")):  # fast, general, general
        path.write_bytes(text.encode())
        check_csv(path)
        (records,) = [csvfile.read_measurement_csv(path)]
        np.testing.assert_array_equal(records.xyz_mm.ravel(), [float(t) for t in signed])
    path.write_bytes(("\ufeff" + body.replace(signed[0], "+-" + texts[0], 1)).encode())
    with pytest.raises(InputError, match="not a finite number"):
        csvfile.read_measurement_csv(path)
