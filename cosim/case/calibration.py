"""Calibration files (``cosim calibrate``): their schema and their loading with the case files
they name (:mod:`cosim.lab.calibrate` runs the search)."""
from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Literal, Optional

from pydantic import Field, ValidationError

from cosim.case.loading import load_case
from cosim.case.messages import schema_error
from cosim.case.paths import resolve_path
from cosim.case.schema import Section
from cosim.errors import CaseError

#: what a calibration target can be, read from a lab run's summary.json
CALIBRATION_QUANTITIES = {
    "peak_friction_angle_deg": "peak friction angle phi_peak [deg]",
    "residual_friction_angle_deg": "residual (triaxial: critical-state) friction angle [deg]",
    "vertical_displacement_end": "direct_shear: vertical displacement of the top plate at the end, dilation + [m]",
    "volumetric_strain_end": "triaxial: volumetric strain at the end, contraction + [-]",
    "void_ratio_change": "void ratio at the end minus after consolidation [-]",
}
#: the quantities only one lab kind measures
CALIBRATION_QUANTITY_KIND = {"vertical_displacement_end": "direct_shear", "volumetric_strain_end": "triaxial"}


class CalibrationTarget(Section):
    quantity: Literal[tuple(CALIBRATION_QUANTITIES)] = Field(
        description="a lab test's result: " + "; ".join(f"{k}: {v}" for k, v in CALIBRATION_QUANTITIES.items()))
    value: float = Field(description="the value to reach (unit of the quantity)")
    tolerance: float = Field(gt=0, description="reached when |achieved - value| <= this (unit of the quantity)")
    normal_stress: float = Field(
        gt=0, le=10e6,
        description="the test's stress this target is for: sigma_n (direct_shear), sigma_3 (triaxial) [Pa]")


class CalibrationParameter(Section):
    name: Literal["friction", "rolling_stiffness", "rolling_friction", "stiffness_ratio"] = Field(
        description="a micro-parameter of the sand material (the case's sand_material): friction mu, "
                    "rolling_stiffness beta_r, rolling_friction eta_r, stiffness_ratio k_n/k_t")
    lower: float = Field(ge=0, description="lower bound [-]")
    upper: float = Field(gt=0, description="upper bound [-]")


class CalibrationFile(Section):
    case: str = Field(description="the direct_shear or triaxial case the search runs on (small: every evaluation "
                                  "is a run per target stress), relative to this file")
    confirm_case: Optional[str] = Field(
        default=None, description="a case of the same kind (full size) run once with the result, relative to this file")
    budget: int = Field(default=20, ge=3, le=500,
                        description="largest number of evaluations (parameter sets), the two bounds' corners included")
    targets: list[CalibrationTarget] = Field(min_length=1, max_length=20, description="[[targets]] tables")
    parameters: list[CalibrationParameter] = Field(min_length=1, max_length=4, description="[[parameters]] tables")


def load_calibration(path):
    """Read and validate a calibration file and the case files it names; returns
    ``(CalibrationFile, case path, confirm case path or None)``. Every failure is a
    CaseError naming the file, the key, the value and what is allowed."""
    path = Path(path)
    if not path.is_file():
        raise CaseError(path, "<file>", str(path), "the calibration file must exist and be a readable TOML file")
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise CaseError(path, "<syntax>", str(exc), "the file must be valid TOML (UTF-8)") from None
    try:
        spec = CalibrationFile.model_validate(raw)
    except ValidationError as exc:
        raise schema_error(path, exc, CalibrationFile) from None
    names = [p.name for p in spec.parameters]
    for i, p in enumerate(spec.parameters):
        if p.name in names[:i]:
            raise CaseError(path, f"parameters[{i}].name", p.name, "each parameter may be given once")
        if p.upper <= p.lower:
            raise CaseError(path, f"parameters[{i}].upper", p.upper,
                            f"must be above lower = {p.lower} (the bounds are reversed or equal)")
        if p.name == "stiffness_ratio" and p.lower <= 0:
            raise CaseError(path, f"parameters[{i}].lower", p.lower, "k_n/k_t must be above 0")
    cases, kinds = [], []
    for key in ("case", "confirm_case"):
        given = getattr(spec, key)
        if given is None:
            cases.append(None)
            continue
        case_path = resolve_path(path, given)
        case, _ = load_case(case_path)  # the case's own errors name the case file
        kind = case.case.kind
        if kind not in ("direct_shear", "triaxial") or (kinds and kind != kinds[0]):
            raise CaseError(path, key, given, f"must be a case of kind 'direct_shear' or 'triaxial', both cases of "
                                              f"one kind (it is '{kind}')")
        kinds.append(kind)
        for i, t in enumerate(spec.targets):
            if CALIBRATION_QUANTITY_KIND.get(t.quantity, kind) != kind:
                raise CaseError(path, f"targets[{i}].quantity", t.quantity,
                                f"a '{kind}' case does not measure it (only '{CALIBRATION_QUANTITY_KIND[t.quantity]}')")
        sand_name = getattr(case, kind).sand_material
        sand = next(m for m in case.dem.materials if m.name == sand_name)
        if "rolling_friction" in names and "rolling_stiffness" not in names and sand.rolling_stiffness == 0:
            raise CaseError(path, "parameters", "rolling_friction",
                            f"the sand of {given} has rolling_stiffness = 0, so a rolling friction does nothing: "
                            "give it a rolling_stiffness or calibrate rolling_stiffness too")
        cases.append(case_path)
    return spec, cases[0], cases[1]
