"""``controller.yaml``'s ``frames:`` section: the calibration's rigid part as the coordinate
frames a Symétrie or PI controller takes (:mod:`hexatherm.core.calibration.frames`).

For each maker, the corrected frames' 12 values (the user/work frame's pose in the
machine frame/ZERO, then the object/tool frame's in the platform frame, mm and deg, the
maker's rotation convention) with their expanded uncertainty (the calibrated joints'
covariance through the rigid fit, :func:`~hexatherm.core.calibration.frames.frames_jacobian`),
and the line or commands that set them where a public client documents it: Symétrie's
gpascii ``C_CFG_CS`` as CGSE sends it. What the frames leave is stated with numbers:
the joints' non-rigid part, and the pose error the calibrated model predicts at the
campaign's targets with and without the frames (the rest is the leg offsets' and
gains', and the non-rigid joints', which only the controller's geometry parameters take).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hexatherm.core.calibration.frames import (
    command,
    corrected_frames,
    fit_frames,
    frame_correction,
    frames_covariance,
)
from hexatherm.core.calibration.model import BASE, PLATFORM
from hexatherm.core.geometry import (
    Convention,
    pose_from_transform,
    to_um_urad,
    transform_from_pose,
)
from hexatherm.devices.symetriepmac import format_command
from hexatherm.workflows.calibrate.run import Calibration

_AXES = ("Tx_mm", "Ty_mm", "Tz_mm", "Rx_deg", "Ry_deg", "Rz_deg")
_PI_AXES = ("X", "Y", "Z", "U", "V", "W")


def _rounded(values: np.ndarray, digits: int = 9) -> list[float]:
    return [round(float(v), digits) + 0.0 for v in values]


def _frame(values: np.ndarray, u: np.ndarray, k: float) -> dict[str, Any]:
    return {
        "pose": dict(zip(_AXES, _rounded(values), strict=True)),
        "U": dict(zip(_AXES, _rounded(k * u, 9), strict=True)),
    }


def _max_error(err: np.ndarray) -> dict[str, float]:
    return {
        "max_translation_um": round(float(np.linalg.norm(err[:, :3], axis=1).max()), 4),
        "max_rotation_urad": round(float(np.linalg.norm(err[:, 3:], axis=1).max()), 4),
    }


def frames_record(run: Calibration, coverage_factor: float = 2.0) -> dict[str, Any]:
    """The ``frames:`` section of ``controller.yaml`` (see the module text)."""
    fit, nominal = run.fit, run.campaign.nominal
    theta, _ = fit.origin_parameters()
    rigid = frame_correction(
        nominal.base_joints_mm,
        nominal.platform_joints_mm,
        theta[BASE:PLATFORM],
        theta[PLATFORM : PLATFORM + 18],
    )
    commanded = run.campaign.commanded
    conv = nominal.convention
    frames = fit_frames(fit.predict, commanded, conv)  # from no frames: never worse
    # the residuals' derivatives by the model's parameters at the optimum (um, urad)
    _, by_theta = fit.model.predict(fit.parameters, command(frames.values, commanded, conv))
    scale = np.array([1e3] * 3 + [np.pi / 180 * 1e6] * 3)
    by_theta = (by_theta * scale[None, :, None]).reshape(-1, by_theta.shape[-1])
    cov = frames.covariance(by_theta, fit.covariance)
    # the frames to set: the fitted ones (relative to the campaign's frame O) composed with
    # those set during the campaign (zero when none: then the same)
    campaign = run.campaign.frames
    during = np.zeros(12) if campaign is None else campaign.values
    written = corrected_frames(frames.values, conv, during)
    cov = frames_covariance(frames.values, cov, conv, during)
    u = np.sqrt(np.maximum(np.diag(cov), 0.0))
    before = to_um_urad(fit.predict(commanded) - commanded)
    out: dict[str, Any] = {
        "what": "the frames that bring the calibrated model's predicted poses closest to the "
        "commanded ones over the campaign's targets (least squares, um and urad, from no "
        "frames: never worse than none), composed with the frames the controller had "
        "during the campaign (calibration.json: controller_frames_during_campaign): the "
        "values to set on it now; U from the fitted parameters' covariance",
        "non_rigid_joints_max_um": {
            "base": round(float(np.linalg.norm(rigid.base_rest_mm, axis=1).max() * 1e3), 4),
            "platform": round(float(np.linalg.norm(rigid.platform_rest_mm, axis=1).max() * 1e3), 4),
        },
        "pose_error_at_targets_predicted": {
            "nominal_controller": _max_error(before),
            "with_these_frames": _max_error(frames.residuals_um_urad),
            "rests_on": "the calibrated model's prediction at the campaign's commanded poses; "
            "what remains with the frames is the leg offsets', gains' and non-rigid joints' "
            "part (legs:), which no frame takes",
        },
    }
    for maker, convention in (("symetrie", "symetrie"), ("pi", "pi")):
        conv_m: Convention = convention  # type: ignore[assignment]
        # the other maker's convention: the same transforms, its angles (their U the
        # same to first order: the frames' angles are small)
        values = written if conv_m == conv else _converted(written, conv, conv_m)
        names = (
            ("user_frame_in_machine", "object_frame_in_platform")
            if maker == "symetrie"
            else ("work_frame_in_zero", "tool_frame_in_platform")
        )
        out[maker] = {
            **_maker_text(maker),
            names[0]: _frame(values[:6], u[:6], coverage_factor),
            names[1]: _frame(values[6:], u[6:], coverage_factor),
        }
        if maker == "symetrie":
            out[maker]["gpascii_line"] = format_command("CFG_CS", [float(v) for v in values], 1)
            m_rad = np.concatenate(
                [
                    values[:3] * 1e-3,
                    np.deg2rad(values[3:6]),
                    values[6:9] * 1e-3,
                    np.deg2rad(values[9:]),
                ]
            )
            out[maker]["api_v2_values_m_rad"] = _rounded(m_rad, 12)
        else:
            out[maker]["gcs_values"] = {
                key: " ".join(f"{a} {v:.9f}" for a, v in zip(_PI_AXES, part, strict=True))
                for key, part in (("work", values[:6]), ("tool", values[6:]))
            }
    return out


def campaign_frames_record(run: Calibration) -> dict[str, Any]:
    """``calibration.json``'s ``controller_frames_during_campaign``: the frames the
    controller had while the sessions were measured, and where that comes from."""
    frames = run.campaign.frames
    values = np.zeros(12) if frames is None else frames.values
    return {
        "user_frame_in_machine": dict(zip(_AXES, _rounded(values[:6], 12), strict=True)),
        "object_frame_in_platform": dict(zip(_AXES, _rounded(values[6:], 12), strict=True)),
        "convention": "symetrie (R = Rz Ry Rx, fixed axes); PI's work and tool frames the same",
        "assumed_zero": frames is None or frames.values_mm_deg is None,
        "source": "no session" if frames is None else frames.source,
        "record": None if frames is None else frames.path,
    }


def campaign_frames_line(run: Calibration) -> str:
    """The screen's line of the frames the campaign was measured with."""
    record = campaign_frames_record(run)
    if record["assumed_zero"]:
        return f"controller frames during the campaign: assumed zero ({record['source']})"
    frames = run.campaign.frames
    assert frames is not None
    shown = ", ".join(f"{v:.6g}" for v in frames.values)
    return (
        f"controller frames during the campaign: user, object [{shown}] (mm, deg; "
        f"{frames.source}); the commanded poses go through them"
    )


def _converted(values: np.ndarray, source: Convention, target: Convention) -> np.ndarray:
    frames = transform_from_pose(np.stack([values[:6], values[6:]]), source)
    return np.asarray(pose_from_transform(frames, target), float).ravel()


def _maker_text(maker: str) -> dict[str, str]:
    if maker == "symetrie":
        return {
            "composition": "platform in machine = U X O^-1 (X: the object's pose in the user "
            "frame, what MOVE#ABS / C_MOVE_PTP command)",
            "convention": "each frame [R t], R = Rz(Rz) Ry(Ry) Rx(Rx) (fixed axes), mm and deg "
            "(gpascii), m and rad (API v2)",
            "set_with": "gpascii (ZONDA, JORAN, PUNA+): gpascii_line, as CGSE's "
            "configure_coordinates_systems sends it; API v2: CFG#CS with the 12 values "
            "(api_v2_values_m_rad; the setter's wire form is not in the public clients "
            "read: check with CFG#CS?3 after setting)",
        }
    return {
        "composition": "platform in ZERO = W X T^-1 (work frame W fixed in space, tool frame "
        "T moving with the platform, X the tool's pose in the work frame, rotations about "
        "the tool's origin): PI's work-and-tool concept as its technical note C887T0007 "
        "is summarised publicly; the note itself was not in the sources searched",
        "convention": "X Y Z (mm) along fixed axes, U V W (deg) in the order U -> V -> W "
        "about axes moving with the platform: R = Rx(U) Ry(V) Rz(W) (PI's hexapod manuals)",
        "set_with": "not documented publicly in a form hexatherm can check: KSW (work) and "
        "KST (tool) take X Y Z U V W (pipython's GCS commands), linked and enabled with "
        "KLN / KEN; whether their values compose as above is PI's (blocked: give "
        "gcs_values to PI's service, or compare KLT? with them before moving)",
    }
