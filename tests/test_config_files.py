"""`--config FILE.toml`: a command's options as a table, each value through the option's own checks; the command line wins."""

import json

from dvrk_dart.cli import _parse, main


def test_a_config_file_gives_the_options_and_the_command_line_wins(tmp_path, capsys):
    config = tmp_path / "replay.toml"
    config.write_text('measured = "two"\nprocessing = "upstream"\nduration = 5.0\nmode = "velocity"\n')
    out = tmp_path / "run"
    assert main(["replay", "--config", str(config), "--duration", "0.3", "--out", str(out)]) == 0
    run_config = json.loads((out / "config.json").read_text())["run_config"]
    assert run_config["measured"] == "two" and run_config["processing"] == "upstream" and run_config["duration_s"] == 0.3


def test_a_bad_config_file_is_one_line_naming_it(tmp_path, capsys):
    for text, words in (('bogus = 1\n', "bogus is not an option of replay"), ('measured = \n', "not a readable TOML file"),
                        ('measured = "no-such-run"\n', "no-such-run"),
                        # argparse read these as options: "expected one argument", help printed with exit 0, "unrecognized 3"
                        ('measured = "--help"\n', "a value does not start with '-'"), ('help = true\n', "help is not an option"),
                        ('duration = [2, 3]\n', "duration takes one value, not a list"),
                        # argparse's "argument --processing: invalid choice" named no file
                        ('processing = "sideways"\n', "processing = 'sideways': not one of upstream, periodic")):
        config = tmp_path / "bad.toml"
        config.write_text(text)
        capsys.readouterr()
        assert main(["replay", "--config", str(config), "--out", str(tmp_path / "never")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and words in err[0], err
        assert not (tmp_path / "never").exists()


def test_an_output_folder_in_a_config_file_is_relative_to_the_file(tmp_path, capsys, monkeypatch):
    """`out = "sub"` went to the current folder (only existing paths were taken
    relative to the file); a number for a folder is refused in one line."""
    configs, elsewhere = tmp_path / "configs", tmp_path / "elsewhere"
    configs.mkdir()
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    config = configs / "replay.toml"
    config.write_text('measured = "two"\nprocessing = "upstream"\nduration = 0.3\nmode = "velocity"\nout = "sub"\n')
    assert main(["replay", "--config", str(config)]) == 0
    assert (configs / "sub" / "config.json").is_file() and not (elsewhere / "sub").exists()
    config.write_text('measured = "two"\nout = 3\n')
    capsys.readouterr()
    assert main(["replay", "--config", str(config)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "out must be a folder path" in err[0] and str(config) in err[0], err


def test_a_boolean_for_an_option_that_takes_a_value_is_one_line(tmp_path, capsys):
    config = tmp_path / "identify.toml"
    config.write_text('runs = ["one"]\nreversal_velocity = true\n')
    assert main(["identify", "--config", str(config), "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "reversal_velocity takes a value, not true" in err[0] and str(config) in err[0], err
    assert not (tmp_path / "never").exists()


def test_config_with_an_equals_sign_is_read_and_a_path_not_beside_it_is_refused(tmp_path, capsys, monkeypatch):
    """`--config=FILE` was ignored (the whole 30 s replayed); a relative file
    missing beside the config file was read from the current folder instead."""
    config = tmp_path / "replay.toml"
    config.write_text('measured = "two"\nprocessing = "upstream"\nduration = 0.3\nmode = "velocity"\n')
    out = tmp_path / "run"
    assert main(["replay", f"--config={config}", "--out", str(out)]) == 0
    assert json.loads((out / "config.json").read_text())["run_config"]["duration_s"] == 0.3
    elsewhere = tmp_path / "elsewhere"
    (elsewhere / "data").mkdir(parents=True)
    (elsewhere / "data" / "run.csv").write_text("0\n")
    monkeypatch.chdir(elsewhere)
    config.write_text('measured = "data/run.csv"\n')
    capsys.readouterr()
    assert main(["replay", "--config", str(config), "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such file beside the config file" in err[0] and str(config) in err[0], err
    assert not (tmp_path / "never").exists()


def test_a_config_value_outside_its_choices_is_named_unless_the_command_line_gives_the_option(tmp_path):
    config = tmp_path / "bad.toml"
    config.write_text('measured = "two"\nprocessing = "sideways"\n')
    assert _parse(["replay", "--config", str(config), "--processing", "upstream"]).processing == "upstream"
