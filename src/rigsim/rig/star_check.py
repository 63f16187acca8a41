"""What ``rigsim rig check`` says about a star-sensor rig: the sensor, its detector, and how far the
``[nominal]`` intrinsics (what the estimators start from) lie from ``[sensor]`` (the instrument) in units of
the σ the nominal states. A nominal that misses the instrument by more than its σ is a warning: the
EKFs' prior claims more than it knows (a calibration pasted into ``[sensor]`` alone, a rig copied from
another sensor)."""

from __future__ import annotations

import math

from rigsim.optics.camera import brown_distort
from rigsim.rig.geometry import GeometryLine
from rigsim.rig.star import StarRig

__all__ = ["nominal_offsets_sigma", "star_summary"]


def nominal_offsets_sigma(rig: StarRig) -> dict[str, float]:
    """|nominal − sensor| in units of the nominal's σ: ``f`` (focal length, px) and ``principal_point``
    (the larger of the two axes). The distortion has no σ in the rig file and is not among them."""
    s, n = rig.sensor, rig.nominal_intrinsics
    f_nom = n.focal_length_mm * 1000.0 / s.pixel_pitch_um
    du = max(abs(a - b) for a, b in zip(n.principal_point_px, s.principal_point_px))
    return {"f": abs(f_nom - s.f_px) / n.focal_length_sigma_px, "principal_point": du / n.principal_point_sigma_px}


def _corner_shift_px(rig: StarRig) -> float:
    """How far apart the nominal's and the sensor's distortion put the detector's corner (px)."""
    s, n = rig.sensor, rig.nominal_intrinsics
    W, H = s.resolution_px
    x, y = (W / 2.0) / s.f_px, (H / 2.0) / s.f_px
    a = brown_distort(x, y, s.k1, s.k2, s.p1, s.p2, 0.0)
    b = brown_distort(x, y, n.k1, n.k2, n.p1, n.p2, 0.0)
    return float(math.hypot(float(a[0]) - float(b[0]), float(a[1]) - float(b[1])) * s.f_px)


def star_summary(rig: StarRig) -> list[GeometryLine]:
    """The sensor, the detector and [nominal] against [sensor], in lines an engineer reads."""
    s, d = rig.sensor, rig.sensor.detector
    n = rig.nominal_intrinsics
    W, H = s.resolution_px
    fu, fv = s.fov_deg
    out = [GeometryLine("sensor", f"{W}×{H} px of {s.pixel_pitch_um:g} µm, f = {s.focal_length_mm:g} mm ({s.f_px:.1f} px), "
                        f"f/{s.f_number:.2f}; field {fu:.2f}° × {fv:.2f}°; PSF σ {s.psf_sigma_px:.2f} px")]
    words = (f" written MSB-aligned in {d.container_bits}-bit words (frame DN = code × {d.code_step_dn})"
             if d.container_bits is not None else "")
    unit = "codes" if d.container_bits is not None else "DN"
    out.append(GeometryLine("detector", f"{d.adc_bits}-bit ADC{words}, offset {d.offset_dn:g} {unit}, gain "
                            f"{d.gain_dn_per_e:g} {unit}/e⁻, read noise {d.read_noise_e:g} e⁻; saturated at "
                            f"{d.saturation_dn} DN"))
    where = "[nominal]" if rig.nominal is not None else "no [nominal]: the design"
    sig = nominal_offsets_sigma(rig)
    f_nom = n.focal_length_mm * 1000.0 / s.pixel_pitch_um
    k = sig["f"]
    out.append(GeometryLine("nominal f", f"{f_nom:.1f} ± {n.focal_length_sigma_px:g} px ({where}); [sensor] {s.f_px:.1f} px: "
                            f"{f_nom - s.f_px:+.1f} px, {k:.1f}σ" + (_MORE if k > 1.0 else ""),
                            "warning" if k > 1.0 else "ok",
                            ("nominal.focal_length_mm", "nominal.focal_length_sigma_px", "sensor.focal_length_mm")))
    k = sig["principal_point"]
    (un, vn), (us, vs) = n.principal_point_px, s.principal_point_px
    out.append(GeometryLine("nominal centre", f"({un:g}, {vn:g}) ± {n.principal_point_sigma_px:g} px; [sensor] ({us:g}, {vs:g}): "
                            f"({un - us:+.1f}, {vn - vs:+.1f}) px, {k:.1f}σ" + (_MORE if k > 1.0 else ""),
                            "warning" if k > 1.0 else "ok",
                            ("nominal.principal_point_px", "nominal.principal_point_sigma_px", "sensor.principal_point_px")))
    out.append(GeometryLine("nominal k1 k2", f"{n.k1:g}, {n.k2:g} (p1 {n.p1:g}, p2 {n.p2:g}); [sensor] {s.k1:g}, {s.k2:g} "
                            f"(p1 {s.p1:g}, p2 {s.p2:g}): {_corner_shift_px(rig):.2f} px apart at the detector's corner "
                            "(the rig states no σ for them: taken as known)"))
    return out


_MORE = (": more than the stated σ (the estimators start from [nominal] and trust it to its σ; set it to what you know "
         "of the instrument, or widen the σ)")
