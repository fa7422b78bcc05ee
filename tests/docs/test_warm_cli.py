"""The warm ``hybridev`` of the docs tests behaves as the console command does."""

import os
import subprocess


def _run(bin_dir, args, cwd):
    env = dict(os.environ, PATH=f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    return subprocess.run(["hybridev", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=300)


def test_exit_codes_streams_and_working_directory(warm_cli, tmp_path):
    warm_cli.write_shim(tmp_path)
    (tmp_path / "work").mkdir()
    ok = _run(tmp_path, ["example-data", "ex"], tmp_path / "work")
    assert ok.returncode == 0, ok.stderr
    assert "wrote ex/schedule.csv" in ok.stdout
    assert (tmp_path / "work" / "ex" / "tariff.csv").is_file()  # the caller's cwd
    bad = _run(tmp_path, ["demo", "--seed", "-1", "--quiet", "--out", "r"], tmp_path / "work")
    assert bad.returncode == 2
    assert bad.stderr.strip().splitlines()[-1].startswith("hybridev demo: error:")
    assert "--seed" in bad.stderr and bad.stdout == ""
    assert not (tmp_path / "work" / "r").exists()


def test_python_on_stdin_runs_in_the_callers_folder_and_fails_like_python(warm_cli, tmp_path):
    py = str(warm_cli.write_python(tmp_path))
    prog = "from pathlib import Path\nPath('x.txt').write_text('hi')\nprint(__name__)\n"
    ok = subprocess.run([py, "-"], input=prog, cwd=tmp_path, capture_output=True, text=True,
                        timeout=300)
    assert ok.returncode == 0 and ok.stdout == "__main__\n", ok.stderr
    assert (tmp_path / "x.txt").read_text() == "hi"
    bad = subprocess.run([py, "-"], input="import math\nmath.sqrt(-1)\n", cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 1 and "ValueError: math domain error" in bad.stderr
    unbound = subprocess.run([py, "-"], input="print(HybridModel)\n", cwd=tmp_path,
                             capture_output=True, text=True, timeout=300)
    assert unbound.returncode == 1 and "NameError" in unbound.stderr  # imports must be written
