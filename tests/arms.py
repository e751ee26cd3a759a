"""The arms the tests run on, passed explicitly like the package does: the
PSM's model (`PSM`) and the PSM with its published parameters (`PSM_ARM`);
where the 105 g runs' weight sat on it (`HAND_PITCH`)."""

from dvrk_dart.io.arm import load_arm
from dvrk_dart.model.description import DEFAULT_MODEL_FILE, resolve_arm_model
from dvrk_dart.model.model_file import load_model

PSM_ARM = load_arm(DEFAULT_MODEL_FILE)
PSM = PSM_ARM.model
MTM = load_model(resolve_arm_model("mtm"))
#: the 105 g runs' hand placement on the pitch link (the data README; pipelines/withheld.toml [payload]): a check, never an input
HAND_PITCH = {"hand_link": "pitch", "hand_reference": "pitch_shaft", "check_horizontal_m": 0.165, "check_height_m": 0.020}
