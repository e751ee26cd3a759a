"""`--config FILE.toml`: a command's options as a TOML table, expanded into
command-line tokens before parsing so that every value goes through its
option's own checks (the parser is cli_parser.py)."""

from __future__ import annotations

import argparse
from pathlib import Path

from dvrk_dart.cli_parser import CONFIG_COMMANDS
from dvrk_dart.errors import DvrkDartError


def expand_config(argv: list[str], parser: argparse.ArgumentParser) -> list[str]:
    """argv with `--config FILE.toml` replaced by the options it holds (those
    not on the command line), so that every value goes through the option's
    own checks; one-line errors name the file."""
    import tomllib

    argv = [part for token in argv for part in (token.split("=", 1) if token.startswith("--config=") else [token])]
    if "--config" not in argv or not argv or argv[0] not in CONFIG_COMMANDS:
        return argv
    at = argv.index("--config")
    if at + 1 >= len(argv):
        raise DvrkDartError("--config: a TOML file is needed")
    path = Path(argv[at + 1])
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise DvrkDartError(f"--config {path}: not a readable TOML file ({str(exc).splitlines()[0]})") from None
    rest = argv[:at] + argv[at + 2:]
    known = _option_actions(parser, argv[0])
    tokens = []
    for key, value in table.items():
        option = "--" + key.replace("_", "-")
        if option not in known or option in ("--config", "--help"):
            raise DvrkDartError(f"--config {path}: {key} is not an option of {argv[0]}")
        takes_list = known[option].nargs in ("+", "*")
        if isinstance(value, list) and not takes_list:
            raise DvrkDartError(f"--config {path}: {key} takes one value, not a list")
        if any(isinstance(v, str) and v.startswith("-") for v in (value if isinstance(value, list) else [value])):
            raise DvrkDartError(f"--config {path}: {key} = {value!r}: a value does not start with '-' (an option's name)")
        if isinstance(value, bool) != (known[option].nargs == 0):
            raise DvrkDartError(f"--config {path}: {key} " + ("is a switch: true or false" if known[option].nargs == 0 else
                                                               f"takes a value, not {str(value).lower()}"))
        if option in OUTPUT_OPTIONS and not isinstance(value, str):
            raise DvrkDartError(f"--config {path}: {key} must be a folder path (a string), not {value!r}")
        if option not in {token.split("=", 1)[0] for token in rest}:  # the command line's own value wins, --opt=value too
            _check_choice(known[option], key, value, path)
            tokens += _tokens(option, value, path)
    return [argv[0], *tokens, *rest[1:]]


def _check_choice(action: argparse.Action, key: str, value, config: Path) -> None:
    """A value outside its option's choices, named with the file (argparse's own message does not name it)."""
    values = value if isinstance(value, list) else [value]
    if action.choices is not None and action.type is None and any(str(v) not in action.choices for v in values):
        raise DvrkDartError(f"--config {config}: {key} = {value!r}: not one of {', '.join(map(str, action.choices))}")


def _option_actions(parser: argparse.ArgumentParser, command: str) -> dict[str, argparse.Action]:
    subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(subparsers.choices[command]._option_string_actions)


#: options whose value is a folder the command writes: relative to the config file even before it exists
OUTPUT_OPTIONS = ("--out", "--report")


#: file names a value with one of these endings, or with a folder in it, is a path (else a name such as 'one')
PATH_SUFFIXES = (".csv", ".bag", ".mcap", ".db3", ".json", ".toml", ".txt")


def _tokens(option: str, value, config: Path) -> list[str]:
    """An option's command-line tokens from a TOML value (a flag from a boolean; a path relative to the config
    file: an output folder always, another value where that file exists, else a run name such as 'one'; a value
    that reads as a path but is not beside the config file is an error, never a file of the current folder)."""
    if isinstance(value, bool):
        return [option] if value else []
    folder = config.parent
    tokens = [option]
    for v in value if isinstance(value, list) else [value]:
        if isinstance(v, str) and (option in OUTPUT_OPTIONS or (folder / v).exists()):
            tokens.append(str(folder / v))
        elif isinstance(v, str) and ("/" in v or v.lower().endswith(PATH_SUFFIXES)) and not Path(v).is_absolute():
            raise DvrkDartError(f"--config {config}: {option.removeprefix('--')} = {v!r}: no such file beside the config file "
                                "(a relative path is read from the config file's folder)")
        else:
            tokens.append(str(v))
    return tokens
