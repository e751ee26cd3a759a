"""Loading the model description, the identified parameters and the
Pinocchio model together, once per process (every command needs them)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path

from dvrk_dart.io.csv_run import say_once
from dvrk_dart.io.reference_data import resolve
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.model_file import load_model
from dvrk_dart.model.identified import IdentifiedModel
from dvrk_dart.model.parameters import IdentifiedParameters, load_parameters


@dataclass(frozen=True)
class Arm:
    model: PsmModel
    params: IdentifiedParameters
    identified: IdentifiedModel


def load_arm(model_file: str | Path, params_file: str | Path | None = None) -> Arm:
    """An arm's description (`model_file`), its identified parameters (default:
    the manifest's params.json of that arm, resolved at run time) and the
    Pinocchio evaluator."""
    return _load_arm(Path(model_file), params_file)


@cache
def _load_arm(model_file: Path, params_file: str | Path | None) -> Arm:
    model = load_model(model_file)
    params = load_parameters(resolve(model.default_parameters, explicit=params_file), model)
    say_once(params.unused_values(model))  # on stderr, whatever the command
    return Arm(model, params, IdentifiedModel(model, params))
