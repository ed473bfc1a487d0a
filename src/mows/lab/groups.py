"""Groups of candidates this table cannot tell apart, and the measurement that would.

- **Groups**: two significant candidates (p < 0.01) cannot be told apart by this data when each
  one's fitted signal, v_A = P_A⊥·r (the residual's projection on A's projected signature),
  lies within the other's signature space: cos(v_A, span B⊥) ≥ 0.95 both ways. Groups are the
  connected sets of such pairs.
- **Separating measurements**: the group's signatures and fitted signals (the fitted linear
  coefficients, extended) are evaluated on the table joined with a what-if variant of it
  (:mod:`mows.lab.whatif`); the cheapest variant after which no pair of the group stays
  indistinguishable is proposed. If none does, each member's independent check is reported
  (e.g. gravity and an unreferenced field act identically on the lever in every rotation: only
  levelling the plane or checking the reference's zero tells them apart).
- **Tie-break inside a group**: members within ΔBIC 2 of the group's best are ordered by
  (fitted parameters inside their physical bounds first, then catalog priority): physics whose
  size is fixed by known constants (static deflection, gravity, finite amplitude, damping,
  transverse gradient) before free calibration errors (field offset, plane tilt, moment scale).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from mows.lab.algebra import Signature, cosine_within, orthonormal_basis, project_out
from mows.lab.candidates import TIE_DELTA_BIC
from mows.lab.whatif import variants

GROUP_COSINE = 0.95
GROUP_SIGNIFICANCE = 0.01


@dataclasses.dataclass
class Group:
    """Candidates this data cannot tell apart, the measurement that would, and direct checks."""

    number: int
    members: list
    separated_by: str | None
    separation: str
    checks: list

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def _indistinguishable(a: Signature, b: Signature) -> bool:
    return (cosine_within(a.fitted_signal, b.basis) >= GROUP_COSINE and
            cosine_within(b.fitted_signal, a.basis) >= GROUP_COSINE)


def _clusters(significant) -> list:
    """Connected sets (of two or more) of indistinguishable candidates, each in tie-break order."""
    by_name = {c.name: c for c in significant}
    parts = _partition({c.name: c.signature for c in significant})
    return [_tie_break([by_name[name] for name in part]) for part in parts if len(part) > 1]


def group_candidates(candidates, fit, probe) -> list:
    """Number the groups by rank, put each group's members together in tie-break order
    (``candidates`` is reordered in place) and find what separates each group."""
    cluster_of = {c.name: members for members in _clusters([c for c in candidates if c.p_value < GROUP_SIGNIFICANCE])
                  for c in members}
    ranked = []
    groups: list[Group] = []
    for candidate in candidates:
        members = cluster_of.get(candidate.name)
        if members is None:
            ranked.append(candidate)
        elif members[0] not in ranked:
            for member in members:
                member.group = len(groups) + 1
            ranked.extend(members)
            groups.append(_separate(members, fit, probe, len(groups) + 1))
    candidates[:] = ranked
    return groups


def _tie_break(members) -> list:
    members = sorted(members, key=lambda c: -c.delta_bic)
    best = members[0].delta_bic
    tied = [c for c in members if c.delta_bic >= best - TIE_DELTA_BIC]
    rest = [c for c in members if c not in tied]
    return sorted(tied, key=lambda c: (not c.within_bounds, c.effect.priority)) + rest


def _partition(signatures: dict) -> list:
    """Connected sets of mutually indistinguishable signatures (names), singletons included."""
    names = list(signatures)
    parent = {name: name for name in names}

    def root(name):
        while parent[name] != name:
            name = parent[name]
        return name

    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if _indistinguishable(signatures[a], signatures[b]):
                parent[root(b)] = root(a)
    found: dict[str, list[str]] = {}  # root → the names in its set
    for name in names:
        found.setdefault(root(name), []).append(name)
    return list(found.values())


def _separate(members, fit, probe, number) -> Group:
    """The cheapest what-if variant that splits the group most; checks for what stays together."""
    names = [c.name for c in members]
    best_variant, best_parts = None, [names]
    # The fitted signal extended to new rows: the same linear coefficients on the joined rows.
    coefficients = {c.name: np.linalg.lstsq(c.signature.projected, c.signature.fitted_signal, rcond=None)[0]
                    for c in members}
    for variant in variants(fit.table, probe):
        joined = variant.table
        model_basis = orthonormal_basis(fit.model_jacobian(joined))
        extended = {}
        for candidate in members:
            columns = np.asarray(fit.extension_columns(candidate.effect, joined))
            projected = project_out(columns, model_basis)
            basis = orthonormal_basis(projected, np.linalg.norm(columns, axis=0).max())
            extended[candidate.name] = Signature(basis, projected, 0.0, basis.shape[1],
                                                 basis.T @ (projected @ coefficients[candidate.name]))
        parts = _partition(extended)
        if len(parts) > len(best_parts):
            best_variant, best_parts = variant, parts
        if len(parts) == len(names):
            break
    together = [part for part in best_parts if len(part) > 1]
    checks = [f"{name}: {next(c for c in members if c.name == name).effect.check}"
              for part in together for name in part]
    if best_variant is None:
        text = ("no variation of angles, amplitude, field or temperature separates them: they act identically "
                "on the lever; check directly")
    else:
        text = f"{best_variant.description}: separates " + " | ".join(", ".join(part) for part in best_parts)
        if together:
            text += "; " + "; ".join(", ".join(part) for part in together) + " still act identically: check directly"
    return Group(number, names, None if best_variant is None else best_variant.name, text, checks)
