"""A stage's first part run ahead (registry ``early``): the same artifacts, or stopped unused."""

import pytest

import debist
from debist.core.forking import fork_workers
from debist.engine import runner as runner_module
from debist.stages import registry

pytestmark = pytest.mark.skipif(fork_workers(2) < 2, reason="needs two cores and POSIX fork")


@pytest.fixture
def children(monkeypatch):
    """Every forked call the runner starts: its label, and whether it was stopped."""
    seen = []

    class Recorded(runner_module.BesideRun):
        def __init__(self, fn, label):
            super().__init__(fn, label)
            self.record = {"label": label, "stopped": False}
            seen.append(self.record)

        def stop(self):
            self.record["stopped"] = True
            super().stop()

    monkeypatch.setattr(runner_module, "BesideRun", Recorded)
    return seen


def test_compare_reads_only_ingest_and_differentiate_in_its_first_part():
    compare = registry.stage("compare")
    assert compare.early == ("ingest", "differentiate")
    assert set(compare.early) < set(compare.upstream)  # validate comes in the second part


def test_the_first_part_run_ahead_gives_the_artifacts_of_a_run_in_turn(synthetic_copy, children):
    """validate and compare recomputed (damaged manifests): compare's peers start beside
    validate, and the run verifies to the digest of the original run, whose compare the
    damaged-manifest test recomputes in turn (tests/cli/test_api.py)."""
    root, digest = synthetic_copy
    for stage in ("validate", "compare"):
        (root / "out" / stage / "manifest.json").write_bytes(b"")
    result = debist.run(root / "wf.toml")
    early = [c for c in children if c["label"] == "stage 'compare' (first part)"]
    assert len(early) == 1 and not early[0]["stopped"]  # started, and its result used
    assert result.digest == digest
    assert debist.verify(root / "wf.toml", digest).ok


def test_a_first_part_whose_stage_stays_up_to_date_is_stopped_unused(synthetic_copy, children):
    """validate recomputed to the same bytes: compare stays up to date, its peers' fit that
    started beside validate is stopped, and nothing of the run changes."""
    root, digest = synthetic_copy
    before = (root / "out/compare/manifest.json").read_bytes()
    (root / "out/validate/manifest.json").write_bytes(b"")
    result = debist.run(root / "wf.toml")
    early = [c for c in children if c["label"] == "stage 'compare' (first part)"]
    assert len(early) == 1 and early[0]["stopped"]
    assert result.digest == digest
    assert (root / "out/compare/manifest.json").read_bytes() == before
