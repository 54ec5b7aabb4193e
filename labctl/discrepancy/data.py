"""Measured points grouped into contact cases: the arrays every fit and check of the workflow runs on."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from labctl.errors import InputError
from labctl.physics.effects import ContactCase, stack_cases
from labctl.physics.validity import check_roller_loads
from labctl.stiffness_table import StiffnessPoint, read_stiffness_table

HDF5_SUFFIXES = (".h5", ".hdf5")
T = TypeVar("T")


@dataclass(frozen=True)
class CaseData:
    """All points measured on one contact case (roller, materials, rail Ra), in file order."""

    case: ContactCase
    load_n: np.ndarray
    ln_stiffness: np.ndarray
    repetition: np.ndarray
    """Repetition number per point, -1 where the table gives none."""

    @property
    def label(self) -> str:
        r = self.case.roller
        name = f"type {r.type_id}" if r.type_id is not None else f"D {r.diameter_m * 1e3:g} mm"
        return (f"{name} (L_we {r.contact_length_m * 1e3:.4g} mm, {r.material.name}, "
                f"rail Ra {self.case.rail_ra_m * 1e6:.3g} µm)")

    def describe(self) -> dict[str, Any]:
        """The case's descriptors at the user's edge (mm, µm)."""
        r = self.case.roller
        return {
            "roller_type": r.type_id,
            "diameter_mm": _edge(r.diameter_m * 1e3),
            "contact_length_mm": _edge(r.contact_length_m * 1e3),
            "material": r.material.name,
            "rail_ra_um": _edge(self.case.rail_ra_m * 1e6),
        }


def _edge(value: float) -> float:
    """A converted value without the last bits of float noise (0.2 µm, not 0.19999999999999998)."""
    return float(f"{value:.12g}")


@dataclass(frozen=True)
class Dataset:
    """The measured points as cases; residual vectors concatenate the cases in this order."""

    cases: tuple[CaseData, ...]
    _design: dict[Any, Any] = field(default_factory=dict, compare=False, repr=False)
    """What depends only on the design (cases, loads, seatings), worked out once: shared by ``with_ln_stiffness``."""

    def design_memo(self, key: Any, make: Callable[[], T]) -> T:
        """``make()``, computed once per design: a quantity of the loads and seatings alone (not of ln k), which every
        campaign ``with_ln_stiffness`` gives (the lack-of-fit reference's draws) shares."""
        if key not in self._design:
            self._design[key] = make()
        return self._design[key]

    @property
    def n_points(self) -> int:
        return int(sum(c.load_n.size for c in self.cases))

    @property
    def ln_stiffness(self) -> np.ndarray:
        return np.concatenate([c.ln_stiffness for c in self.cases])

    @cached_property
    def load_n(self) -> np.ndarray:
        load = np.concatenate([c.load_n for c in self.cases])
        load.setflags(write=False)  # computed once and shared: nobody may change it in place
        return load

    @cached_property
    def stacked_case(self) -> ContactCase:
        """All cases as one per-point case (``stack_cases``): a law evaluated on it covers every point at once."""
        return stack_cases([c.case for c in self.cases], [c.load_n.size for c in self.cases])

    @property
    def load_per_length_n_per_m(self) -> np.ndarray:
        """F/L_we of every point (the roller's effective contact length)."""
        return self.load_n / self.stacked_case.roller.contact_length_m

    def case_slices(self) -> list[slice]:
        """Where each case's points sit in the concatenated vectors."""
        out, start = [], 0
        for c in self.cases:
            out.append(slice(start, start + c.load_n.size))
            start += c.load_n.size
        return out

    def case_of(self, point: int) -> int:
        """The case (its position in ``cases``) of point ``point``, an index into the concatenated vectors."""
        return next(i for i, sl in enumerate(self.case_slices()) if sl.start <= point < sl.stop)

    def subset(self, keep: Iterable[int]) -> Dataset:
        return Dataset(tuple(self.cases[i] for i in keep))

    def with_ln_stiffness(self, ln_k: np.ndarray) -> Dataset:
        """The same campaign (cases, loads, seatings) with ln k replaced by ``ln_k`` (cases concatenated)."""
        return Dataset(tuple(replace(c, ln_stiffness=np.asarray(ln_k[s], dtype=float))
                             for c, s in zip(self.cases, self.case_slices(), strict=True)), self._design)

    def run_ids(self) -> np.ndarray:
        """Seating index per point: one per (roller case, repetition); a point without a repetition number is
        its own seating. Points of one seating share its random offset in the statistical model."""
        return self.design_memo("run_ids", self._make_run_ids)

    def _make_run_ids(self) -> np.ndarray:
        """``run_ids``, worked out once per design: every fit and noise whitening asks for it (read-only)."""
        ids = np.empty(self.n_points, dtype=int)
        next_id = 0
        for c, sl in zip(self.cases, self.case_slices(), strict=True):
            reps = c.repetition
            known = np.unique(reps[reps >= 0])
            lookup = {int(r): next_id + i for i, r in enumerate(known)}
            next_id += known.size
            local = np.empty(reps.size, dtype=int)
            for i, r in enumerate(reps):
                if r >= 0:
                    local[i] = lookup[int(r)]
                else:
                    local[i] = next_id
                    next_id += 1
            ids[sl] = local
        ids.setflags(write=False)
        return ids

    def roller_keys(self) -> list[tuple[float, float]]:
        """Distinct roller geometries (D, L_we) in case order: the units a held-out check leaves out."""
        return list(dict.fromkeys(_roller_key(c) for c in self.cases))

    def roller_groups(self) -> list[list[int]]:
        """The case indices of each roller geometry, in ``roller_keys`` order."""
        return [[i for i, c in enumerate(self.cases) if _roller_key(c) == k] for k in self.roller_keys()]

    def roller_index(self) -> np.ndarray:
        """Each point's roller geometry, as its position in ``roller_keys``."""
        keys = {k: g for g, k in enumerate(self.roller_keys())}
        return np.concatenate([np.full(c.load_n.size, keys[_roller_key(c)]) for c in self.cases])

    def drop_points(self, drop: np.ndarray) -> Dataset:
        """The dataset without the points flagged in ``drop`` (a mask over the concatenated points)."""
        out = []
        for c, sl in zip(self.cases, self.case_slices(), strict=True):
            keep = ~drop[sl]
            if np.any(keep):
                out.append(CaseData(c.case, c.load_n[keep], c.ln_stiffness[keep], c.repetition[keep]))
        return Dataset(tuple(out))

    def repetitions(self) -> list[int]:
        """Distinct repetition numbers present (empty when the table gives none)."""
        reps = np.unique(np.concatenate([c.repetition for c in self.cases]))
        return [int(r) for r in reps if r >= 0]

    def select_repetitions(self, keep: Callable[[np.ndarray], np.ndarray]) -> Dataset:
        """The points whose repetition passes ``keep`` (a mask function); cases left empty are dropped."""
        out = []
        for c in self.cases:
            m = keep(c.repetition)
            if np.any(m):
                out.append(CaseData(c.case, c.load_n[m], c.ln_stiffness[m], c.repetition[m]))
        return Dataset(tuple(out))


def _roller_key(c: CaseData) -> tuple[float, float]:
    return (c.case.roller.diameter_m, c.case.roller.contact_length_m)


def build_dataset(points: Sequence[StiffnessPoint]) -> Dataset:
    """Group points by contact case (first-seen order); refuses empty input and non-physical values."""
    if not points:
        raise InputError("no measured points: give at least one stiffness table or campaign file with data")
    groups: dict[ContactCase, list[StiffnessPoint]] = {}
    for i, p in enumerate(points):
        for name in ("load_n", "stiffness_n_per_m"):
            v = getattr(p, name)
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"measured point {i + 1}: {name} = {v!r}, expected a positive number")
        groups.setdefault(p.case(), []).append(p)
    cases = []
    for case, pts in groups.items():
        cases.append(CaseData(
            case=case,
            load_n=np.array([p.load_n for p in pts], dtype=float),
            ln_stiffness=np.log(np.array([p.stiffness_n_per_m for p in pts], dtype=float)),
            repetition=np.array([-1 if p.repetition is None else p.repetition for p in pts], dtype=int),
        ))
    return Dataset(tuple(cases))


def load_points(paths: Sequence[str | Path]) -> list[StiffnessPoint]:
    """Read stiffness tables (CSV) and campaign files (HDF5) into one list of points."""
    if not paths:
        raise InputError("give at least one measured file (stiffness-table CSV or campaign HDF5)")
    points: list[StiffnessPoint] = []
    for path in paths:
        if Path(path).suffix.lower() in HDF5_SUFFIXES:
            points.extend(_campaign_points(Path(path)))
        else:
            table = read_stiffness_table(path)
            for row, p in enumerate(table, 2):
                if _is_ball(p):
                    raise InputError(f"{path}: row {row}: diameter_mm = contact_length_mm = roller_length_mm = "
                                     f"{p.diameter_m * 1e3:g} is a ball (Hertz point contact), not a roller; "
                                     "labctl discrepancy compares rollers with line-contact models: give the "
                                     "roller rows alone")
            check_roller_loads(str(path), ((f"row {row}", p.case().roller, p.case().rail, p.load_n)
                                           for row, p in enumerate(table, 2)))  # the models apply there only
            points.extend(table)
    return points


def _is_ball(p: StiffnessPoint) -> bool:
    """A ball run as the rig stores it: a 'roller' whose diameter, contact length and length are all the ball's."""
    return p.roller_type is None and p.roller_length_m is not None and \
        p.diameter_m == p.contact_length_m == p.roller_length_m


def _campaign_points(path: Path) -> list[StiffnessPoint]:
    try:
        from labctl.storage import CampaignReader
        from labctl.storage.table import stiffness_points
    except ImportError:
        raise InputError(f"{path}: reading campaign HDF5 files needs labctl.storage, which is not available in "
                         "this installation; export the campaign as a stiffness-table CSV instead") from None
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    with CampaignReader(path) as reader:
        for series in reader.series_indices():
            spec = reader.specimen(series)
            if spec.kind == "ball":
                raise InputError(f"{path}: series {series} is a ball run ({spec.label or 'ball'}, diameter "
                                 f"{float(spec.ball_diameter_m or spec.diameter_m) * 1e3:g} mm): labctl "
                                 "discrepancy compares rollers with line-contact models, a ball is the rig's Hertz "
                                 "check (labctl report compares it with Hertz): give the roller campaigns alone")
        points = stiffness_points(reader)
    if not points:
        raise InputError(f"{path}: the campaign holds no processed stiffness points")
    return points


def campaign_setup_stiffness(paths: Sequence[str | Path]) -> float | None:
    """K_setup of the rig stored in the campaign files among ``paths`` (None when there are none).

    Campaigns whose stored rigs disagree cannot share one setup term: that is refused (give ``--rig``).
    """
    values: dict[float, str] = {}
    for path in paths:
        if Path(path).suffix.lower() not in HDF5_SUFFIXES or not Path(path).is_file():
            continue
        from labctl.physics.rig_config import load_rig, rig_from_text
        from labctl.storage import CampaignReader

        with CampaignReader(path) as reader:
            text = reader.config_text("rig.toml")
        rig = rig_from_text(text, f"{path}:/config/rig.toml") if text else load_rig()
        values.setdefault(rig.setup_stiffness_n_per_m, str(path))
    if len(values) > 1:
        listed = ", ".join(f"{f} ({k:.4g} N/m)" for k, f in values.items())
        raise InputError(f"the campaigns were processed with different K_setup: {listed}; give --rig FILE to say "
                         "which the setup term is relative to, or analyse them separately")
    return next(iter(values), None)
