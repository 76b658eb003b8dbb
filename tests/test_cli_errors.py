"""CLI under bad input: outputs and formats checked before any simulation,
plain progress without a terminal, messages that fit the command, summary
lines that name every file, help pages with examples and defaults."""

import json
import os
import subprocess
import sys
import time

import pytest
from treebake.cli import main

SAPLING = "grammars/sapling.lsys"
QUICK = ["--duration", "0.5", "--fps", "12", "--quality", "draft"]


def run(*args, env=None, timeout=300):
    return subprocess.run([sys.executable, "-m", "treebake.cli", *map(str, args)],
                          capture_output=True, text=True, check=False, timeout=timeout,
                          env={**os.environ, **(env or {})})


@pytest.fixture(scope="module")
def small_bake(root, tmp_path_factory):
    out = tmp_path_factory.mktemp("bake")
    assert main(["bake", str(root / SAPLING), *QUICK, "--out", str(out), "-q"]) == 0
    return out / "sapling" / "sapling.npz"


@pytest.fixture
def blocked(tmp_path):
    """An output folder no one can create, root included: its parent is a file."""
    wall = tmp_path / "a-file"
    wall.write_text("not a folder")
    return wall / "out"


def test_unwritable_output_is_a_clear_error_before_any_work(root, small_bake, blocked, capsys):
    started = time.perf_counter()
    commands = [
        ["bake", root / SAPLING, "--out", blocked],  # full duration: would take long
        ["export", small_bake, "--out", blocked],
        ["preview", small_bake, "--out", blocked],
        ["inspect", root / SAPLING, "--out", blocked],
        ["derive", root / SAPLING, "-o", blocked / "modules.txt"],
    ]
    for args in commands:
        capsys.readouterr()
        assert main([str(a) for a in args]) == 2, args
        err = capsys.readouterr().err
        assert "cannot write" in err and str(blocked) in err, (args, err)
        assert "simulating" not in err and "Traceback" not in err
    assert time.perf_counter() - started < 20  # nothing was simulated


def test_unknown_format_fails_before_simulating(root, tmp_path, capsys):
    for fmt in ("fbx", "glb,fbx"):
        assert main(["bake", str(root / SAPLING), "--out", str(tmp_path), "--format", fmt]) == 2
        err = capsys.readouterr().err
        assert "unknown export format 'fbx'" in err and "simulating" not in err
    assert not list(tmp_path.rglob("*.npz"))


def test_empty_export_format_is_an_error(small_bake, tmp_path, capsys):
    assert main(["export", str(small_bake), "--out", str(tmp_path), "--format", ""]) == 2
    assert "names no export format" in capsys.readouterr().err
    assert not list(tmp_path.rglob("*.glb"))


def test_bake_of_a_bake_says_what_to_do(small_bake, capsys):
    assert main(["bake", str(small_bake)]) == 2
    err = capsys.readouterr().err
    assert "is a bake, not a scene" in err and "treebake export" in err and "UTF-8" not in err


def test_module_limit_messages_name_options_the_command_has(tmp_path):
    big = tmp_path / "big.lsys"
    big.write_text("axiom: F\niterations: 30\nF -> FF\n")
    bake = run("bake", big, "--out", tmp_path)
    assert bake.returncode == 2 and "exceeds" in bake.stderr
    assert "--max-modules" not in bake.stderr and "iterations" in bake.stderr
    derive = run("derive", big, "--max-modules", "100")
    assert derive.returncode == 2 and "raise --max-modules" in derive.stderr


def test_plain_progress_lines_without_a_terminal(root, tmp_path):
    r = run("bake", root / SAPLING, *QUICK, "--out", tmp_path, "--format", "glb",
            env={"TREEBAKE_PROGRESS_SECONDS": "0"})
    assert r.returncode == 0, r.stderr
    lines = [x for x in r.stderr.splitlines() if x.startswith("simulating: ")]
    assert len(lines) >= 3 and "done in" in lines[-1]  # periodic, then the end
    assert "\r" not in r.stderr and "[#" not in r.stderr  # no bar redraws in a log
    assert any(x.startswith("exporting glb: 1/1") for x in r.stderr.splitlines())
    quiet = run("bake", root / SAPLING, *QUICK, "--out", tmp_path, "-q")
    assert quiet.stderr == ""


def test_summary_lines_in_order_naming_every_file_or_sequence(root, tmp_path):
    r = run("bake", root / SAPLING, *QUICK, "--out", tmp_path, "--format", "glb,obj")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].startswith("baked 1 tree (1 simulated, 57 segments), 7 frames in ")
    assert lines[0].endswith("sapling.npz")
    assert lines[1].startswith("exported ") and "sapling.glb" in lines[1]
    assert "manifest.json" in lines[1] and "obj/sapling.####.obj (7 files, 0001-0007)" in lines[1]
    manifest = json.loads((tmp_path / "sapling" / "manifest.json").read_text())
    assert f"exported {len(manifest['files']) + 1} files," in lines[1]
    assert lines[2].startswith("keyframes: ")
    assert " 1 files" not in r.stdout and "1 trees" not in r.stdout


def test_negative_duration_reads_as_a_sentence(root):
    r = run("bake", root / SAPLING, "--duration", "-5")
    assert r.returncode == 2 and "--duration -5 is out of range [0, 3600] s" in r.stderr
    assert ": =" not in r.stderr


@pytest.mark.parametrize("flag, value, message", [
    ("--fps", "-1", "--fps -1 is out of range [1, 1000] 1/s"),
    ("--seed", "-1", "--seed -1 is out of range [0, 9223372036854775807]"),
    ("--wind", "500", "--wind 500 is out of range [0, 120] m/s"),
])
def test_a_flag_out_of_range_is_the_flags_error_not_the_files(flag, value, message, capsys):
    """A flag's bad value named the scene or grammar file (`demo.toml: fps =
    -1 ...`) though the file holds no such value."""
    assert main(["bake", "preset:demo", flag, value]) == 2
    err = capsys.readouterr().err
    assert message in err and "demo.toml" not in err, err


def test_a_files_own_bad_value_still_names_the_file(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text('duration = -5\n[[tree]]\ngrammar = "sapling"\n')
    assert main(["bake", str(scene), "--fps", "12"]) == 2
    assert f"{scene}: duration = -5 is out of range [0, 3600] s" in capsys.readouterr().err


COMMANDS = ["derive", "inspect", "bake", "export", "preview", "diff", "batch", "sway", "list",
            "accuracy", "stability"]


@pytest.mark.parametrize("command", COMMANDS)
def test_help_pages_have_examples_and_every_option_explained(command, capsys):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = capsys.readouterr().out
    assert "examples:\n  treebake " + command in text
    assert "%%" not in text
    from treebake.cli import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command").choices[command]
    for action in sub._actions:
        if action.dest == "help":
            continue
        assert action.help, f"{command} {action.option_strings or action.dest} has no help"
        if action.option_strings and action.default not in (None, False) and \
                not isinstance(action.default, bool):
            assert "default" in action.help, f"{command} {action.option_strings}: no default"


def test_help_lists_the_valid_names():
    """The help pages' lists are the modules' own (kept out of the parser so
    every command starts fast)."""
    from treebake import cli
    from treebake.accuracy import SCENARIOS, SPECIES
    from treebake.stress_cases import cases

    assert tuple(SPECIES) == cli.ACCURACY_SPECIES
    assert tuple(SCENARIOS) == cli.ACCURACY_SCENARIOS
    assert tuple(c.name for c in cases(True)) == cli.STABILITY_CASES
    assert "gusty" in run("accuracy", "--help").stdout
    assert "'near-zero segments'" in run("stability", "--help").stdout


def test_help_describes_the_solvers_and_engines_there_are(capsys):
    """`bake --solver planar` is the planar LOD (linear tier, pymunk tier,
    MuJoCo reference), not "pymunk"; `stability --engine` has no
    articulated tier any more."""
    from treebake.cli import build_parser

    def option(command, flag):
        sub = next(a for a in build_parser()._actions if a.dest == "command").choices[command]
        return next(a for a in sub._actions if flag in a.option_strings)

    solver = option("bake", "--solver").help
    assert solver.startswith("planar: the planar LOD (default): a linear tier for whole trees")
    assert "fast pymunk" not in solver and "full: the MuJoCo reference for everything" in solver
    engine = option("stability", "--engine")
    assert engine.choices == ("auto", "pymunk") and "docs/physics.md" in engine.help
    with pytest.raises(SystemExit) as exc:
        main(["stability", "--engine", "articulated"])
    assert exc.value.code == 2 and "invalid choice: 'articulated'" in capsys.readouterr().err


def test_nesting_too_deep_is_a_scene_error_not_a_traceback(tmp_path):
    """A scene or job file with arrays nested 900 deep hit Python's
    recursion limit inside the TOML reader: a traceback, exit 1."""
    deep = "[" * 900 + "1" + "]" * 900
    for command, name in (("bake", "deep.toml"), ("batch", "jobs.toml")):
        path = tmp_path / name
        path.write_text(f"duration = {deep}\n")
        r = run(command, path, "--out", tmp_path / "out")
        assert r.returncode == 2, r.stderr
        assert "nested too deep" in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_a_folder_given_as_a_grammar_says_so(tmp_path):
    folder = tmp_path / "oak.lsys"
    folder.mkdir()
    r = run("bake", folder, "--out", tmp_path / "out")
    assert r.returncode == 2 and "is a folder, not a grammar file" in r.stderr, r.stderr


def test_closed_stdout_or_stderr_is_no_traceback(root, tmp_path):
    """`treebake bake ... >&-` wrote its files, then failed to flush a
    closed stdout (exit 1); `2>&-` crashed before any work."""
    out = tmp_path / "out"
    for closed in (1, 2):
        done = subprocess.run([sys.executable, "-m", "treebake.cli", "bake", str(root / SAPLING),
                               *QUICK, "--out", str(out)], stdin=subprocess.DEVNULL,
                              **{("stdout" if closed == 1 else "stderr"): subprocess.DEVNULL},
                              check=False, close_fds=True,
                              preexec_fn=lambda c=closed: os.close(c))
        assert done.returncode == 0
        assert (out / "sapling" / "sapling.npz").is_file()
    bad = subprocess.run([sys.executable, "-m", "treebake.cli", "bake", str(tmp_path / "no.lsys")],
                         stdout=subprocess.DEVNULL, check=False, preexec_fn=lambda: os.close(2))
    assert bad.returncode == 2


TYPO = ("B takes 2 parameters in its productions (B(w,n)); B(w*0.45) has 1 and will never be "
        "rewritten")


@pytest.fixture
def typo(root, tmp_path):
    """Issue 42's sapling: `B(w*0.45)` for `B(w*0.45,5)` on line 17, column 48."""
    path = tmp_path / "typo.lsys"
    path.write_text((root / SAPLING).read_text().replace("B(w*0.45,5)", "B(w*0.45)"))
    return path


def test_a_grammar_warning_is_printed_and_strict_makes_it_an_error(typo, capsys):
    assert main(["derive", str(typo), "--stats-only"]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err[0] == f"treebake: warning: {typo}:17:48: {TYPO}"
    assert len(err) == 2 and err[1].startswith("sapling: 98 modules")  # then the derivation
    for command in (["derive", str(typo)], ["inspect", str(typo), "--out", str(typo.parent)]):
        assert main([*command, "--strict"]) == 2, command
        out, err = capsys.readouterr()
        assert err == f"treebake: error: {typo}:17:48: {TYPO}\n" and out == "", command
    assert not (typo.parent / "sapling").exists()  # inspect wrote nothing
    # `2>&-`: the warning goes nowhere, the work is done
    done = subprocess.run([sys.executable, "-m", "treebake.cli", "derive", str(typo)],
                          stdout=subprocess.PIPE, text=True, check=False,
                          preexec_fn=lambda: os.close(2))
    assert done.returncode == 0 and "@leaves(1)B(0.02025)]" in done.stdout


def test_a_scene_s_grammar_warnings_once_per_file_and_strict_before_any_work(typo, tmp_path,
                                                                             capsys):
    scene = tmp_path / "two.toml"
    scene.write_text('name = "two"\n[[tree]]\ngrammar = "typo.lsys"\n'
                     '[[tree]]\ngrammar = "typo.lsys"\nposition = [3.0, 0.0]\n'
                     '[[tree]]\ngrammar = "sapling"\nposition = [0.0, 6.0]\n')
    out = tmp_path / "out"
    assert main(["bake", str(scene), "--out", str(out), "--strict"]) == 2  # full duration
    assert capsys.readouterr().err == f"treebake: error: {typo}:17:48: {TYPO}\n"
    assert not out.exists()
    assert main(["bake", str(scene), *QUICK, "--out", str(out), "-q"]) == 0
    assert capsys.readouterr().err == f"treebake: warning: {typo}:17:48: {TYPO}\n"
    jobs = tmp_path / "jobs.toml"
    jobs.write_text('[[job]]\nscene = "two.toml"\n[[job]]\ngrammar = "typo.lsys"\n')
    assert main(["batch", str(jobs), "--out", str(tmp_path / "batch"), "--strict"]) == 2
    assert capsys.readouterr().err == f"treebake: error: {typo}:17:48: {TYPO}\n"
    assert not (tmp_path / "batch").exists()


def test_the_eta_counts_from_the_first_report_not_the_stages_before(monkeypatch, capsys):
    """A 10,000-tree bake grows and rigs for 12 s before its first report;
    counted in, its first ETA read 1,966 s for a 96 s simulation."""
    from treebake import cli_progress

    clock = iter([0.0, 100.0, 100.0, 100.0, 110.0, 110.0, 110.0, 120.0, 120.0])
    monkeypatch.setattr(cli_progress.time, "perf_counter", lambda: next(clock))
    monkeypatch.setenv("TREEBAKE_PROGRESS_SECONDS", "0")
    show = cli_progress.progress_bar("simulating")  # t = 0: the bar, before growing
    show(0.0, 1.0)  # t = 100 s: the simulation starts
    show(0.5, 1.0)  # t = 110 s: half done in 10 s
    show(1.0, 1.0)  # t = 120 s
    lines = capsys.readouterr().err.splitlines()
    assert lines == ["simulating: 0 %, estimating", "simulating: 50 %, 10 s left",
                     "simulating: done in 20.0 s"]


def test_no_eta_from_the_first_few_frames(monkeypatch, capsys):
    """Under 2 % done, the rate is a few frames' noise: preset:felling read
    "510 s left" after its first second, for a 65 s bake."""
    from treebake import cli_progress

    now = [0.0]
    monkeypatch.setattr(cli_progress.time, "perf_counter", lambda: now[0])
    monkeypatch.setenv("TREEBAKE_PROGRESS_SECONDS", "0")
    show = cli_progress.progress_bar("simulating")
    show(0.0, 1.0)
    now[0] = 1.0
    show(0.002, 1.0)  # 0.2 % done in 1 s
    now[0] = 3.0
    show(0.05, 1.0)  # 5 % done in 3 s
    lines = capsys.readouterr().err.splitlines()
    assert lines == ["simulating: 0 %, estimating", "simulating: 0 %, estimating",
                     "simulating: 5 %, 57 s left"]


@pytest.mark.parametrize("args, message", [
    (["bake", "sapling", "--workers", "0"], "--workers must be >= 1, got 0"),
    (["batch", "JOBS", "--jobs", "0"], "--jobs must be >= 1, got 0"),
    (["diff", "BAKE", "BAKE", "--position-tolerance", "-1"],
     "--position-tolerance must be >= 0, got -1.0"),
    (["diff", "BAKE", "BAKE", "--angle-tolerance", "nan"], "--angle-tolerance must be >= 0, got nan"),
])
def test_counts_and_tolerances_out_of_range_are_refused(args, message, small_bake, tmp_path,
                                                        root, capsys):
    """0 workers was taken as every core, and a negative tolerance called two
    identical bakes DIFFERENT (exit 1): both are exit 2 with the flag named."""
    jobs = tmp_path / "jobs.toml"
    jobs.write_text(f'[[job]]\ngrammar = "{root / SAPLING}"\nduration = 0.1\n')
    args = [str(small_bake) if a == "BAKE" else str(jobs) if a == "JOBS" else a for a in args]
    assert main([*args, "--out", str(tmp_path)] if args[0] != "diff" else args) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err, err
    assert not (tmp_path / "sapling").exists() and not (tmp_path / "j").exists()


def test_a_log_reader_that_leaves_does_not_stop_the_bake(root, tmp_path):
    """`bake ... 2>&1 | head -1` killed the bake with the first progress
    line after head left (exit 141, no .npz); the lines stop, the work not."""
    proc = subprocess.Popen([sys.executable, "-m", "treebake.cli", "bake", str(root / SAPLING),
                             *QUICK, "--out", str(tmp_path)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    proc.stdout.readline()  # the first line, then the reader is gone
    proc.stdout.close()
    assert proc.wait(timeout=300) == 141  # the summary line had nowhere to go
    assert (tmp_path / "sapling" / "sapling.npz").is_file()
    # the log's reader gone from the start, the report's still there: exit 0
    log_gone = subprocess.Popen([sys.executable, "-m", "treebake.cli", "bake",
                                 str(root / SAPLING), *QUICK, "--out", str(tmp_path / "b")],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    log_gone.stderr.close()
    report = log_gone.stdout.read()
    assert log_gone.wait(timeout=300) == 0 and report.startswith(b"baked 1 tree"), report


def test_an_unknown_flag_gets_the_commands_usage_and_the_closest_flag(capsys):
    """`bake sapling --fomat glb` printed the top level's usage
    (`treebake [-h] [--version] COMMAND ...`) and no hint."""
    with pytest.raises(SystemExit) as stop:
        main(["bake", "sapling", "--fomat", "glb"])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: treebake bake ") and "COMMAND ..." not in err
    assert "treebake bake: error: unrecognized arguments: --fomat glb; " \
           "--fomat: did you mean --format?" in err


def test_paths_that_are_not_what_a_command_takes_say_what_they_are(tmp_path, capsys):
    """A folder given to diff said 'file not found'; an output folder under a
    file said 'Not a directory'; a job file's list of formats was called
    comma-separated and npz was missing from the choices."""
    wall = tmp_path / "afile"
    wall.write_text("x")
    jobs = tmp_path / "jobs.toml"
    jobs.write_text('[[job]]\ngrammar = "sapling"\nformats = ["xyz"]\n')
    cases = [(["diff", str(tmp_path), str(tmp_path)],
              f"{tmp_path}: is a folder, not a bake (.npz) or glTF export (.glb, .gltf)"),
             (["bake", "sapling", "--out", str(wall / "x"), "--duration", "0.1"],
              f"{wall} is a file, not a folder"),
             (["bake", str(tmp_path / "none.toml")], "none.toml: scene file not found"),
             (["batch", str(jobs)], "choose from: glb, gltf, obj, usd, usda, abc, preview, "
                                    "or npz (the bake itself)")]
    for args, message in cases:
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert message in err and "comma" not in err, err
