"""The held-out search space: every setting debist chooses on held-out data, in one table.

Each :class:`Choice` of :data:`SEARCH_SPACE` names an ``[identify]`` field, its candidates
(simplest first), the column of the one-standard-error rule's parsimony order that ranks
them (:data:`debist.identify.autotune.PARSIMONY`) and when debist chooses it (a predicate on
the section as written and the data). The search (:func:`held_out_search`) runs in steps:

1. a workflow's own ``[identify.auto]`` table is searched as given
   (:func:`workflow_search`), and nothing below runs;
2. otherwise every entry whose predicate holds contributes its candidates, in table order;
3. an entry's screen drops candidates the whole estimation data already decide (the
   slip elements the least squares leaves at zero stiffness, :func:`inert_slip`); an entry
   left with one candidate needs no search, one left with more joins the grid last (the
   order of the search's rows, and of the sweep of a large grid);
4. the remaining grid is scored by blocked cross-validation of the free run
   (:func:`debist.identify.autotune.select_hyperparameters`), the most parsimonious
   candidate within one paired standard error of the best chosen;
5. if every candidate fails, the configuration's own values are kept (the fallback), and
   the search reports itself undecided.

References
----------
Masoud & Maas 2025, Eq. 37-41; Hastie, Tibshirani & Friedman 2009, Sec. 7.10 (model
selection by K-fold cross-validation, one-standard-error rule); Al-Bender, Lampaert &
Swevers 2005, IEEE Trans. Autom. Control 50(11) (generalised Maxwell slip); Ljung 1999,
System Identification, 2nd ed., Sec. 13.2 (persistent excitation).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from debist.core.errors import IdentificationError
from debist.identify.autotune import AutoResult, auto_settings, select_hyperparameters
from debist.identify.config import IdentifyConfig
from debist.identify.fit import Record, fit_rbf_model

__all__ = [
    "SEARCH_SPACE",
    "Choice",
    "Facts",
    "HeldOut",
    "held_out_grid",
    "held_out_search",
    "inert_slip",
    "workflow_search",
]


@dataclass(frozen=True)
class Facts:
    """What the entries' predicates read: the section as written and the data.

    Attributes
    ----------
    section : mapping
        The ``[identify]`` section as written (before defaults).
    cfg : IdentifyConfig or None
        The configuration after the support check (``M`` the supported size); None before
        the data are read.
    thin : bool
        Whether an estimation record is one spectral line or one repeated period
        (:func:`debist.identify.excitation.thin_data`).
    """

    section: Mapping[str, Any]
    cfg: IdentifyConfig | None = None
    thin: bool = False

    def left_open(self, key: str) -> bool:
        """Whether the workflow states neither ``key`` nor an ``[identify.auto]`` table."""
        return key not in self.section and self.section.get("auto") is None


@dataclass(frozen=True)
class Choice:
    """One setting the held-out search may choose.

    Attributes
    ----------
    key : str
        The :class:`~debist.identify.config.IdentifyConfig` field.
    candidates : callable
        ``candidates(cfg) -> tuple``: the values tried, simplest first, given the
        configuration after the support check.
    rank : str
        The column of :data:`debist.identify.autotune.PARSIMONY` that breaks a tie between
        the candidates (``n_params``: fewer regressor columns first).
    applies : callable
        ``applies(facts) -> bool``: whether debist chooses the setting (:class:`Facts`).
    screen : callable or None
        ``screen(records, cfg, candidates) -> (kept, note)``: drops candidates the whole
        estimation data decide, with a note saying which and why (``""``: none).
    when : str
        The predicate in words, for the documentation.
    """

    key: str
    candidates: Callable[[IdentifyConfig | None], tuple[Any, ...]]
    rank: str
    applies: Callable[[Facts], bool]
    screen: Callable[[Sequence[Record], IdentifyConfig, list], tuple[list, str]] | None = None
    when: str = ""


def inert_slip(
    records: Sequence[Record], cfg: IdentifyConfig, candidates: list
) -> tuple[list, str]:
    """Drop slip-element counts the least squares gives zero stiffness on the whole data.

    The stiffnesses k_e >= 0 of the Maxwell-slip elements are bounded below by zero; where
    the fit on all estimation records puts every one at that bound, the count is the model
    without elements and needs no cross-validation (a rig without hysteresis in q).

    Parameters
    ----------
    records : sequence of Record
        Estimation records.
    cfg : IdentifyConfig
        The configuration the candidates modify; screened only when it has no elements.
    candidates : list
        The ``slip`` candidates (``False`` or a count).

    Returns
    -------
    kept : list
        The candidates without the inert counts.
    note : str
        What was dropped and why, or ``""``.

    References
    ----------
    Al-Bender, Lampaert & Swevers 2005 (Maxwell-slip elements); Hastie, Tibshirani &
    Friedman 2009, Sec. 7.10 (the simpler of equal models).
    """
    if cfg.n_slip:
        return list(candidates), ""
    inert = []
    for count in (c for c in candidates if c is not False):
        try:
            model, _ = fit_rbf_model(records, replace(cfg, slip=count, bootstrap=0))
        except IdentificationError:
            continue
        if not np.any(np.asarray(model.theta_slip) > 0):
            inert.append(count)
    if not inert:
        return list(candidates), ""
    listed = ", ".join(str(c) for c in inert)
    return [c for c in candidates if c not in inert], (
        f"slip = {listed}: the least squares on the estimation data gives every element "
        "zero stiffness (no hysteresis to explain), so these are the model without elements"
    )


#: Every setting debist may choose on held-out data, in the order the grid lists them.
SEARCH_SPACE: tuple[Choice, ...] = (
    Choice(
        key="slip",
        candidates=lambda cfg: (False, 2, 4),
        rank="n_params",
        applies=lambda facts: facts.left_open("slip"),
        screen=inert_slip,
        when="not stated",
    ),
    Choice(
        key="M",
        candidates=lambda cfg: tuple(range(2, cfg.M + 1)),
        rank="n_params",
        applies=lambda facts: (
            facts.left_open("M") and facts.cfg is not None and facts.cfg.M > 2 and facts.thin
        ),
        when="not stated, thin data, more than 2 supported centres",
    ),
)


def held_out_grid(facts: Facts) -> dict[str, list]:
    """Return the candidates of the settings a workflow leaves to debist.

    Parameters
    ----------
    facts : Facts
        The section as written and the data.

    Returns
    -------
    dict of str to list
        Per entry of :data:`SEARCH_SPACE` whose predicate holds, its candidates, in table
        order; empty when the section has an ``[identify.auto]`` table.

    References
    ----------
    Hastie, Tibshirani & Friedman, The Elements of Statistical Learning, 2nd ed., 2009,
    Sec. 7.10 (model selection by cross-validation).
    """
    return {c.key: list(c.candidates(facts.cfg)) for c in SEARCH_SPACE if c.applies(facts)}


def workflow_search(
    records: Sequence[Record], cfg: IdentifyConfig
) -> tuple[IdentifyConfig, AutoResult | None]:
    """Search a workflow's own ``[identify.auto]`` grid (step 1 of the search).

    Parameters
    ----------
    records : sequence of Record
        Estimation records.
    cfg : IdentifyConfig
        The configuration; its ``auto`` table is the grid and options
        (:func:`debist.identify.config.auto_settings`).

    Returns
    -------
    cfg : IdentifyConfig
        Without ``auto``, with the chosen values (unchanged without the table).
    search : AutoResult or None
        The search, None without the table.

    Raises
    ------
    WorkflowError
        For an invalid table.
    IdentificationError
        If every candidate failed or diverged.

    References
    ----------
    Hastie, Tibshirani & Friedman 2009, Sec. 7.10 (one-standard-error rule).
    """
    if cfg.auto is None:
        return cfg, None
    grid, options = auto_settings(cfg)
    search = select_hyperparameters(records, replace(cfg, auto=None), grid, **options)
    return replace(cfg, auto=None, **search.chosen), search


@dataclass(frozen=True)
class HeldOut:
    """Outcome of :func:`held_out_search`.

    Attributes
    ----------
    cfg : IdentifyConfig
        The configuration with the chosen values.
    search : AutoResult or None
        The cross-validation, None when no grid was left to score.
    note : str
        What the screens dropped and why (``""``: nothing).
    seconds : float
        Wall time [s] of the screens and the search.
    """

    cfg: IdentifyConfig
    search: AutoResult | None
    note: str
    seconds: float


def held_out_search(records: Sequence[Record], cfg: IdentifyConfig, facts: Facts) -> HeldOut:
    """Choose the settings a workflow leaves open (steps 2-5 of the search).

    Parameters
    ----------
    records : sequence of Record
        Estimation records (never validation data).
    cfg : IdentifyConfig
        The configuration after the support check, without ``auto``.
    facts : Facts
        The section as written and the data, for the entries' predicates.

    Returns
    -------
    HeldOut
        The chosen configuration, the search, the screens' note.

    Raises
    ------
    ResourceError
        If a free run would exceed the memory budget.

    References
    ----------
    Masoud & Maas 2025, Eq. 37-41; Hastie, Tibshirani & Friedman 2009, Sec. 7.10.
    """
    t0 = time.perf_counter()
    grid, notes = held_out_grid(facts), []
    for choice in SEARCH_SPACE:
        if choice.screen is not None and choice.key in grid:
            kept, note = choice.screen(records, cfg, grid[choice.key])
            if kept == grid[choice.key]:
                continue
            notes.append(note)
            del grid[choice.key]
            if len(kept) > 1:  # screened: it joins the grid last
                grid[choice.key] = kept
    search = None
    if grid:
        search = select_hyperparameters(records, cfg, grid, fallback=True)
        cfg = replace(cfg, **search.chosen)
    return HeldOut(cfg, search, "; ".join(notes), time.perf_counter() - t0)
