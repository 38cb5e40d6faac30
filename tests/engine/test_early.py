"""A stage's first part run ahead (registry ``early``): the same artifacts, or stopped unused."""

import dataclasses
import os
import subprocess
import sys

import pytest

import debist
from debist.core.forking import fork_workers
from debist.engine import runner as runner_module
from debist.identify.physics_prior import analytical_for, physics_mass
from debist.physics.freerun import analytical_model
from debist.physics.params import PrototypeParams
from debist.physics.reduced import fit_reduced
from debist.physics.statics import StaticsError
from debist.stages import compare, registry, study
from debist.validate.config import ValidateConfig

needs_fork = pytest.mark.skipif(fork_workers(2) < 2, reason="needs two cores and POSIX fork")


@pytest.fixture
def children(monkeypatch):
    """Every forked call the runner starts: its label, and whether it was stopped."""
    seen = []

    class Recorded(runner_module.BesideRun):
        def __init__(self, fn, label, **options):
            super().__init__(fn, label, **options)
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


@needs_fork
def test_the_first_part_run_ahead_gives_the_artifacts_of_a_run_in_turn(
    synthetic_copy, children, monkeypatch
):
    """validate and compare recomputed (damaged manifests): compare's peers start beside
    validate, and the run verifies to the digest of the original run, whose compare the
    damaged-manifest test recomputes in turn (tests/cli/test_api.py)."""
    root, digest = synthetic_copy
    for stage in ("validate", "compare"):
        (root / "out" / stage / "manifest.json").write_bytes(b"")
    preloads = []  # (process, children started before) of each compare.preload call
    real = compare.preload
    monkeypatch.setattr(
        compare, "preload", lambda ctx: (preloads.append((os.getpid(), len(children))), real(ctx))
    )
    result = debist.run(root / "wf.toml")
    early = [c for c in children if c["label"] == "stage 'compare' (first part)"]
    assert len(early) == 1 and not early[0]["stopped"]  # started, and its result used
    # loaded here, once, before the first part's process was forked
    assert preloads == [(os.getpid(), children.index(early[0]))]
    assert result.digest == digest
    assert debist.verify(root / "wf.toml", digest).ok


@needs_fork
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


class _Inputs:
    """The two parts of a runner that ``compare.preload`` reads."""

    def __init__(self, physics, narx):
        self._physics, self._narx = physics, narx

    def physics(self):
        return self._physics

    def stage_config(self, stage):
        return {"sindy": {"narx": {"enabled": self._narx}}, "validate": {}}


def test_preload_builds_the_analytical_model_that_the_first_part_and_identify_then_reuse():
    """A prototype no other test builds (b moved by 1 um): preload fits its reduced model
    once; what the forked first part calls (analytical_for) and identify's m_q = "physics"
    then come from that fit, with no fit of their own."""
    physics = dataclasses.replace(PrototypeParams.paper(), b=PrototypeParams.paper().b + 1e-6)
    before = fit_reduced.cache_info()
    compare.preload(_Inputs(physics, narx=False))
    loaded, built = fit_reduced.cache_info(), analytical_model.cache_info()
    assert loaded.misses == before.misses + 1
    model = analytical_for(physics, [], ValidateConfig.from_dict({}))
    m_q = physics_mass(physics)
    after = fit_reduced.cache_info()
    assert analytical_model.cache_info().hits == built.hits + 1  # the first part's call
    assert after.misses == loaded.misses and after.hits == loaded.hits + 1  # identify's
    assert m_q == pytest.approx(float(model.model.curves([0.0]).m_q[0]), rel=1e-12)


def test_preload_leaves_a_failing_model_to_the_stages_and_imports_sysidentpy(monkeypatch):
    """A prototype whose static path fails raises nothing here (the stage that needs its
    model reports it); with the NARX peer on, SysIdentPy is loaded for the child to inherit."""
    pytest.importorskip("sysidentpy")

    def no_path(physics):
        raise StaticsError("the static path cannot be continued")

    monkeypatch.setattr(compare, "analytical_model", no_path)
    compare.preload(_Inputs(PrototypeParams.paper(), narx=True))
    assert "sysidentpy.model_structure_selection" in sys.modules


@needs_fork
def test_a_beside_stage_s_preload_runs_here_before_its_process_is_forked(
    synthetic_copy, children, monkeypatch
):
    """The study added to a complete run, validate recomputed: the study starts in its own
    process beside validate, its module's preload having run in this process just before."""
    root, _ = synthetic_copy
    wf = root / "wf.toml"
    wf.write_text(
        wf.read_text() + "\n[study]\nM = [4]\nsigma_n = [0.5]\nalpha = [1e-6]\nmax_samples = 800\n"
    )
    (root / "out" / "validate" / "manifest.json").write_bytes(b"")
    preloads = []  # (process, children started before) of each study.preload call
    real = study.preload
    monkeypatch.setattr(
        study, "preload", lambda ctx: (preloads.append((os.getpid(), len(children))), real(ctx))
    )
    debist.run(wf)
    forked = [c for c in children if c["label"] == "stage 'study'"]
    assert len(forked) == 1 and not forked[0]["stopped"]
    assert preloads == [(os.getpid(), children.index(forked[0]))]
    assert (root / "out" / "study" / "rbf_grid.parquet").is_file()


def test_the_study_preload_loads_the_signal_tools_and_the_figure_class():
    """In a fresh process: neither loaded before, both after (what the forked study inherits;
    scipy.signal's own submodules, as the lazy stub debist's modules hold loads none)."""
    code = (
        "import sys; import debist.stages.study as s\n"
        "wanted = ('scipy.signal._signaltools', 'matplotlib.figure')\n"
        "before = [m in sys.modules for m in wanted]\n"
        "s.preload(None)\n"
        "print(before, [m in sys.modules for m in wanted])\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["[False,", "False]", "[True,", "True]"]
