"""The settings phrase of the Chapter 3 figures is read from the task objects."""

from __future__ import annotations

import pytest

from vslbook.envs.robot import make_task
from vslbook.experiments.ch3_settings import CODE, THESIS, settings_phrase


def test_the_defaults_are_the_authors_settings() -> None:
    """Fig. 3.1: the joint cost without the base joint; Fig. 3.2: beer pong's in-cup term
    and contacts, table tennis's K = 1000 and punishments; Fig. 3.5: no public code."""
    assert CODE == "the authors' settings (SVSL_LMOE code)"
    assert settings_phrase("planar-reacher") == f"{CODE}: joint cost without the base joint"
    assert settings_phrase("beer-pong") == f"{CODE}: in-cup term and contacts"
    assert settings_phrase("table-tennis-ch3") == f"{CODE}: K = 1000 at full, punishments"
    assert settings_phrase("reacher5-ch3") == f"{THESIS} (no public code for the 5-link reacher)"


@pytest.mark.parametrize(
    "name, options, want",
    [
        ("planar-reacher", {"exclude_base_joint": False}, f"{THESIS}: A.3.1's joint cost -‖θ‖²"),
        ("beer-pong", {"reward": "thesis"}, f"{THESIS}: A.3.2's reward"),
        ("table-tennis-ch3", {"settings": "thesis"},
         f"{CODE}: K = 1000 at full; {THESIS}: A.3.3's punishments"),
    ],
)  # fmt: skip
def test_the_phrase_follows_the_task_object(name, options, want) -> None:
    task = make_task(name, **options)
    try:
        assert settings_phrase(name, task) == want
    finally:
        task.close()
