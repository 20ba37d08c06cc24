"""Pipelines of named stages: how every front end states its method, step by step.

A front end declares its own tuple of :class:`Stage` (nothing here knows which stages
exist): each is a function ``(state, config) -> state`` with a name and a predicate
saying whether the configuration asks for it. :func:`run_pipeline` runs them in order,
times each and keeps a :class:`StageRecord` of what it changed, which
``imagemap synthesize --verbose`` logs and ``--report`` writes.

A state is any object with a ``changed`` attribute: a stage sets it to a line on what
it did.

Examples
--------
>>> from dataclasses import dataclass
>>> @dataclass
... class Count:
...     value: int = 0
...     changed: str = ""
>>> def add(state, config):
...     state.value += config
...     state.changed = f"+{config}"
...     return state
>>> stages = (Stage("add", add), Stage("again", add, lambda config: config > 5))
>>> state, records = run_pipeline(Count(), 2, stages)
>>> state.value, [(r.name, r.changed) for r in records]
(2, [('add', '+2'), ('again', 'off')])
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar

__all__ = ["Stage", "StageRecord", "run_pipeline"]

log = logging.getLogger("imagemap")


class _State(Protocol):
    changed: str


StateT = TypeVar("StateT", bound=_State)
ConfigT = TypeVar("ConfigT")


def _always(config: Any) -> bool:
    return True


@dataclass(frozen=True)
class Stage(Generic[StateT, ConfigT]):
    """A named step of a pipeline: ``run(state, config) -> state``, run when
    ``wanted(config)``."""

    name: str
    run: Callable[[StateT, ConfigT], StateT]
    wanted: Callable[[ConfigT], bool] = _always


@dataclass(frozen=True)
class StageRecord:
    """What a stage did in one run: its seconds and a line on what it changed
    ("off" when the configuration did not ask for it)."""

    name: str
    seconds: float
    changed: str


def run_pipeline(
    state: StateT, config: ConfigT, stages: Sequence[Stage[StateT, ConfigT]]
) -> tuple[StateT, list[StageRecord]]:
    """Run ``stages`` on ``state`` in order; returns the final state and a record per stage.

    Parameters
    ----------
    state : object with a ``changed`` attribute
        What the stages hand on to each other.
    config : object
        The front end's configuration, read by every stage and predicate (never changed).
    stages : sequence of Stage

    Returns
    -------
    state : the final state
    records : list of StageRecord
    """
    records = []
    for stage in stages:
        if not stage.wanted(config):
            records.append(StageRecord(stage.name, 0.0, "off"))
            continue
        start = time.perf_counter()
        state.changed = ""
        state = stage.run(state, config)
        seconds = time.perf_counter() - start
        records.append(StageRecord(stage.name, seconds, state.changed))
        log.info("stage %s: %.3f s; %s", stage.name, seconds, state.changed)
    state.changed = ""
    return state, records
