"""The arms the tests run on, passed explicitly like the package does: the
PSM's model (`PSM`) and the PSM with its published parameters (`PSM_ARM`)."""

from dvrk_dart.io.arm import load_arm
from dvrk_dart.model.description import DEFAULT_MODEL_FILE, resolve_arm_model
from dvrk_dart.model.model_file import load_model

PSM_ARM = load_arm(DEFAULT_MODEL_FILE)
PSM = PSM_ARM.model
MTM = load_model(resolve_arm_model("mtm"))
