"""``train.init_from``: a run that starts from the weights of a checkpoint or a Monodepth2 model folder."""

from __future__ import annotations

from pathlib import Path

from ..checkpoint import load_state_into, read_weights
from ..errors import PoseconsError
from ..monodepth2 import read_monodepth2

# The model keys that fix the networks' weights and what their outputs mean: a run can start from
# weights whose config differs in anything else (image size, losses, data, training).
ARCHITECTURE = ("num_layers", "scales", "pose_mirror")


def load_initial_weights(model, path: str | Path) -> str:
    """``train.init_from``: the weights, nothing else, of a checkpoint (``.pt``, ``.safetensors``) or a
    Monodepth2 model folder into ``model``, whose architecture they must have. Returns how the run
    was initialised, for its records."""
    path = Path(path)
    if path.is_dir():
        config, weights, origin = read_monodepth2(path)
    else:
        config, weights, state = read_weights(path)
        step = f"step {state['step']}; " if state.get("step") is not None else ""
        origin = f"{path} ({step}initialised: {state.get('initialisation', 'not recorded')})"
    theirs, ours = config.model, model.config.model
    differ = [
        f"model.{k} {getattr(theirs, k)} (the run: {getattr(ours, k)})"
        for k in ARCHITECTURE
        if getattr(theirs, k) != getattr(ours, k)
    ]
    if differ:
        raise PoseconsError(
            f"{path}: its architecture is not the run's: {', '.join(differ)}; give the run the same with --set"
        )
    load_state_into(model, weights, path)
    return f"weights of {origin}"
