"""Calibration files (``cosim calibrate``): their schema and their loading with the case files
they name (:mod:`cosim.lab.calibrate` runs the search)."""
from __future__ import annotations

import tomllib
from dataclasses import dataclass
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
    case: Optional[str] = Field(
        default=None, description="the case this target is measured on, relative to this file (default: the file's "
                                  "case; e.g. a loose specimen's case beside a dense one)")
    confirm_case: Optional[str] = Field(
        default=None, description="the full-size case that confirms this target (default: the file's confirm_case "
                                  "for a target on the file's case, none for a target with its own case)")


#: the grains' aspect ratio a two-sphere rod can have (its members touch at 2)
ASPECT_RATIO_RANGE = (1.0, 2.0)


class CalibrationParameter(Section):
    name: Literal["friction", "rolling_stiffness", "rolling_friction", "stiffness_ratio", "aspect_ratio"] = Field(
        description="a micro-parameter of the sand material (the case's sand_material): friction mu, "
                    "rolling_stiffness beta_r, rolling_friction eta_r, stiffness_ratio k_n/k_t; or the grains' "
                    "shape, aspect_ratio: length over width of a rod of two equal spheres, 1 to 2, which replaces "
                    "the case's one [[dem.clumps]] template (specimen.grains = 'clumps'; each value makes its own "
                    "specimen)")
    lower: float = Field(ge=0, description="lower bound [-]")
    upper: float = Field(gt=0, description="upper bound [-]")


def rod_members(aspect_ratio):
    """The [[dem.clumps]] members of a rod of two equal spheres (radius 1) whose length over
    width is ``aspect_ratio``: centres ±(A − 1) along x, so the length is 2 (A − 1) + 2 = 2 A
    and the width 2."""
    half = float(aspect_ratio) - 1.0
    return [[-half, 0.0, 0.0, 1.0], [half, 0.0, 0.0, 1.0]]


@dataclass
class CalibrationSetup:
    """A calibration file read: ``spec`` (:class:`CalibrationFile`), and per target (in the
    order of ``spec.targets``) the case it is measured on and the case that confirms it (a
    Path, or None)."""
    spec: "CalibrationFile"
    cases: list
    confirm_cases: list


class CalibrationFile(Section):
    case: str = Field(description="the direct_shear or triaxial case the search runs on (small: every evaluation "
                                  "is a run per target stress), relative to this file")
    confirm_case: Optional[str] = Field(
        default=None, description="a case of the same kind (full size) run once with the result, relative to this file")
    set: list[str] = Field(
        default_factory=list,
        description="--set overrides (section.key=value, the value in TOML) applied to every case this file names, "
                    "before the parameters: e.g. the grains made clumps in sphere cases")
    budget: int = Field(default=20, ge=3, le=500,
                        description="largest number of evaluations (parameter sets), the two bounds' corners included")
    targets: list[CalibrationTarget] = Field(min_length=1, max_length=20, description="[[targets]] tables")
    parameters: list[CalibrationParameter] = Field(min_length=1, max_length=4, description="[[parameters]] tables")


def load_calibration(path) -> CalibrationSetup:
    """Read and validate a calibration file and the case files it names (its own and its
    targets'). Every failure is a CaseError naming the file, the key, the value and what is
    allowed."""
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
    _check_parameters(path, spec.parameters)
    kinds, checked = [], {}

    def case_at(key, given):
        """The case file ``given`` (relative to this file) under ``key``, validated once."""
        case_path = resolve_path(path, given)
        if not case_path.is_file():
            raise CaseError(path, key, given, f"no case file {case_path} (a path relative to this calibration file)")
        if case_path not in checked:
            case, _ = load_case(case_path, spec.set)  # the case's own errors name the case file
            kind = case.case.kind
            if kind not in ("direct_shear", "triaxial") or (kinds and kind != kinds[0]):
                raise CaseError(path, key, given, f"must be a case of kind 'direct_shear' or 'triaxial', every case "
                                                  f"of one kind (it is '{kind}')")
            kinds.append(kind)
            _check_case_for(path, key, given, case, spec.parameters)
            checked[case_path] = kind
        return case_path

    main_case = case_at("case", spec.case)
    main_confirm = None if spec.confirm_case is None else case_at("confirm_case", spec.confirm_case)
    cases, confirms = [], []
    for i, t in enumerate(spec.targets):
        cases.append(main_case if t.case is None else case_at(f"targets[{i}].case", t.case))
        if t.confirm_case is not None:
            confirms.append(case_at(f"targets[{i}].confirm_case", t.confirm_case))
        else:  # the file's confirmation for a target on the file's case; none for a target with its own
            confirms.append(main_confirm if t.case is None else None)
        if CALIBRATION_QUANTITY_KIND.get(t.quantity, kinds[0]) != kinds[0]:
            raise CaseError(path, f"targets[{i}].quantity", t.quantity,
                            f"a '{kinds[0]}' case does not measure it (only '{CALIBRATION_QUANTITY_KIND[t.quantity]}')")
    return CalibrationSetup(spec, cases, confirms)


def _check_parameters(path, parameters):
    """Each parameter once, its bounds in order and within what it can be."""
    names = [p.name for p in parameters]
    for i, p in enumerate(parameters):
        if p.name in names[:i]:
            raise CaseError(path, f"parameters[{i}].name", p.name, "each parameter may be given once")
        if p.upper <= p.lower:
            raise CaseError(path, f"parameters[{i}].upper", p.upper,
                            f"must be above lower = {p.lower} (the bounds are reversed or equal)")
        if p.name == "stiffness_ratio" and p.lower <= 0:
            raise CaseError(path, f"parameters[{i}].lower", p.lower, "k_n/k_t must be above 0")
        if p.name == "aspect_ratio":
            low, high = ASPECT_RATIO_RANGE
            if p.lower < low:
                raise CaseError(path, f"parameters[{i}].lower", p.lower, f"a grain's aspect ratio is at least {low:g}")
            if p.upper > high:
                raise CaseError(path, f"parameters[{i}].upper", p.upper,
                                f"at most {high:g}: the two spheres of a longer rod would not touch")


def _check_case_for(path, key, given, case, parameters):
    """What the parameters need of a case: a rolling stiffness for a rolling friction to act,
    clumps of one shape for the aspect ratio to set."""
    names = [p.name for p in parameters]
    sand_name = getattr(case, case.case.kind).sand_material
    sand = next(m for m in case.dem.materials if m.name == sand_name)
    if "rolling_friction" in names and "rolling_stiffness" not in names and sand.rolling_stiffness == 0:
        raise CaseError(path, "parameters", "rolling_friction",
                        f"the sand of {given} has rolling_stiffness = 0, so a rolling friction does nothing: "
                        "give it a rolling_stiffness or calibrate rolling_stiffness too")
    if "aspect_ratio" in names and (case.specimen.grains != "clumps" or len(case.dem.clumps) != 1):
        raise CaseError(path, key, given, f"the parameter aspect_ratio shapes the grains of a case with "
                                          f"specimen.grains = 'clumps' and one [[dem.clumps]] template (it has "
                                          f"grains = '{case.specimen.grains}' and {len(case.dem.clumps)})")
