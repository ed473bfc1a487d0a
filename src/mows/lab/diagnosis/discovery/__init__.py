"""Discovery beyond the catalog: which physics the residual follows when no catalog effect
explains it, found in the channel of the potential where it acts, and written as the plugin that
adds it back (docs/model_lab.md, "When the catalog has no answer").

Modules, in the order of the search: :mod:`.library` (the covariates and their monomials),
:mod:`.channels` (the potential's channels and their Jacobians: a term is a channel times a
monomial), :mod:`.selection` (the sparse path and its stability over half-samples), :mod:`.refit`
(strengths, significance, cross-validated gain), :mod:`.readings` (each term's family, physical
reading, and the readings that fit as well with the measurement that tells them apart),
:mod:`.plugin_source` (the plugin file in the term's channel), :mod:`.found` (the result and its
report lines) and :mod:`.search` (:func:`discover`, end to end).
"""

from mows.lab.diagnosis.discovery.channels import CHANNELS, Channel
from mows.lab.diagnosis.discovery.found import DiscoveredTerm, Discovery, TermFit
from mows.lab.diagnosis.discovery.library import model_covariates
from mows.lab.diagnosis.discovery.plugin_source import WHY, Plugin
from mows.lab.diagnosis.discovery.search import discover

__all__ = [
    "CHANNELS",
    "WHY",
    "Channel",
    "DiscoveredTerm",
    "Discovery",
    "Plugin",
    "TermFit",
    "discover",
    "model_covariates",
]
