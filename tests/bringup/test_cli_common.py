"""The command-line helpers: an output checked before the work, errors as one line."""

from __future__ import annotations

from tactile_bringup.cli_common import output_problem, run_main


def test_run_main_turns_an_io_error_into_one_line(capsys):
    def body() -> int:
        raise PermissionError(13, "Permission denied", "/data/run/report.json")

    assert run_main(body) == 1
    assert capsys.readouterr().err == "error: Permission denied: /data/run/report.json\n"


def test_output_problems(tmp_path):
    f = tmp_path / "f"
    f.write_text("")
    assert output_problem(tmp_path / "new" / "deeper" / "r.json", "--report") is None  # created when written
    assert output_problem(tmp_path / "out", "--out", folder=True) is None
    assert output_problem(tmp_path, "--out", folder=True) is None
    assert output_problem(f, "--out", folder=True) == f"--out {f}: is a file"
    assert output_problem(tmp_path, "--plot") == f"--plot {tmp_path}: is a folder"
    assert output_problem(f / "x.png", "--plot") == f"--plot {f / 'x.png'}: {f} is not a folder"
    assert list(tmp_path.iterdir()) == [f]  # nothing created, the probe's file removed
