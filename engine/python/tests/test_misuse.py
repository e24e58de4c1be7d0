"""Misuse that once crashed the interpreter or started thousands of threads: every case is a Python
exception with a message that says what to do, never a segfault, a hang or an unchecked count."""

import os
import shutil
import subprocess
import sys
import tempfile
import textwrap

import pytest

import actengine


def test_policy_of_none_is_a_type_error():
    with pytest.raises(TypeError, match="engine must be an actengine.Engine, not None"):
        actengine.Policy(None)


@pytest.mark.parametrize("call", [
    lambda p: p.select_action({}),
    lambda p: p.reset(),
    lambda p: p.will_infer_next(),
])
def test_a_policy_made_without_init_is_refused(call):
    policy = actengine.Policy.__new__(actengine.Policy)
    with pytest.raises(TypeError, match=r"this actengine.Policy was never initialised .*actengine.Policy\(\.\.\.\)"):
        call(policy)


@pytest.mark.parametrize("call", [
    lambda e: e.infer({}),
    lambda e: e.infer_normalized({}),
    lambda e: e.threads,
    lambda e: e.model_info,
])
def test_an_engine_made_without_init_is_refused(call):
    engine = actengine.Engine.__new__(actengine.Engine)
    with pytest.raises(TypeError, match="this actengine.Engine was never initialised"):
        call(engine)


def test_a_scheduler_made_without_init_is_refused():
    scheduler = actengine.ChunkScheduler.__new__(actengine.ChunkScheduler)
    with pytest.raises(TypeError, match="this actengine.ChunkScheduler was never initialised"):
        scheduler.clear()
    with pytest.raises(TypeError, match="never initialised"):
        scheduler.action_at(0)


@pytest.mark.parametrize("threads", [-5, 257, 100000])
def test_convert_refuses_thread_counts_outside_the_limit(act_tiny, tmp_path, threads):
    with pytest.raises(ValueError, match=rf"threads must be in 0..256 \(0 = one per online core\), got {threads}"):
        actengine.convert(act_tiny.dir, tmp_path / "m.actb", "fp32", threads=threads)
    assert not (tmp_path / "m.actb").exists()


def test_engine_refuses_thread_counts_above_the_limit(tiny_blob):
    with pytest.raises(ValueError, match="threads = 2000 is above the limit of 256"):
        actengine.Engine(tiny_blob, threads=2000)


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="needs root, to run a child as nobody (RLIMIT_NPROC does not bind root)")
def test_a_thread_the_os_refuses_is_an_exception(tiny_blob):
    # The n-th pthread_create really fails: a child run as nobody with RLIMIT_NPROC 3 asks for 16.
    folder = tempfile.mkdtemp(prefix="act_nproc_")
    try:
        os.chmod(folder, 0o755)
        blob = os.path.join(folder, "model.actb")
        shutil.copy(tiny_blob, blob)
        os.chmod(blob, 0o644)
        script = textwrap.dedent(f"""
            import resource, actengine
            resource.setrlimit(resource.RLIMIT_NPROC, (3, 3))
            try:
                actengine.Engine({blob!r}, threads=16)
                print("opened")
            except RuntimeError as e:
                print("refused:", e)
        """)
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
        run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60, env=env,
                             user=65534, group=65534, check=False)
        assert run.returncode == 0, run.stderr  # not std::terminate (-6) nor a segfault
        assert "refused: cannot start thread" in run.stdout, run.stdout + run.stderr
        assert "of 16: the operating system refused it" in run.stdout and "use fewer threads" in run.stdout
    finally:
        shutil.rmtree(folder)
