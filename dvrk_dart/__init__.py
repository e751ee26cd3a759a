"""dvrk_dart: a DART simulator of the dVRK Patient Side Manipulator, validated
against the identified dynamic model (Wang et al. 2019) and the real robot."""

__version__ = "0.1.0"
