"""PPO policy files that load without running code.

A stable-baselines3 ``.zip`` keeps the model's parameters as pickles (the ``:serialized:``
entries of its ``data``), and unpickling runs whatever the file's author put there: a
policy file would be code. ``tfalda-sim train`` therefore writes the policy as

- ``tfalda_policy.json``: the network's architecture in plain JSON (the observation and
  action spaces as shapes and bounds, ``net_arch``, the activation, the few switches
  ``ActorCriticPolicy`` is built with);
- ``policy.pth``: its weights, a state dict that ``torch.load(weights_only=True)`` reads
  (tensors only; any other object in it is refused by torch).

``load_policy`` builds the ``ActorCriticPolicy`` that JSON describes and loads the weights
into it. A file holding pickled objects (an SB3 save, its checkpoints) is refused unless
the caller trusts its source (``trust=True``, ``--trust-policy``): then SB3's own loader
reads it, unpickling included.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
from pathlib import Path
from typing import IO, Any

import numpy as np

META_ENTRY = "tfalda_policy.json"
"""The architecture entry of a policy file (the mark of the safe format)."""

WEIGHTS_ENTRY = "policy.pth"
"""The weights entry: the policy's state dict, tensors only."""

FORMAT = "tfalda-sim PPO policy"
FORMAT_VERSION = 1

MAX_META_BYTES = 1 << 20
MAX_WEIGHTS_BYTES = 1 << 30
"""Largest entries read (a 64-64 policy's weights are ≈ 60 kB): a bigger one is no policy
of ours and must not exhaust the memory."""

ACTIVATIONS: tuple[str, ...] = ("Tanh", "ReLU", "LeakyReLU", "ELU", "GELU", "SiLU",
                                "Sigmoid", "Identity")
"""The ``torch.nn`` activations a policy file may name (looked up in this list only: the
file never picks an arbitrary attribute)."""

PICKLE_SUFFIXES: tuple[str, ...] = (".pkl", ".pickle")


class PolicyFileError(ValueError):
    """A policy file that is no PPO policy the agents can drive the env with."""


class UntrustedPolicyError(PolicyFileError):
    """A policy file with pickled objects, refused because its source is not trusted."""


def untrusted_message(path: Path, what: str) -> str:
    return (f"{path} holds pickled Python objects ({what}), and a policy file with pickled "
            "objects can run code when loaded; add --trust-policy (trust=True in Python) if "
            "you trust its source")


def _not_ours(path: Path, reason: str) -> PolicyFileError:
    return PolicyFileError(
        f"{path} is not a PPO policy saved by `tfalda-sim train` ({reason}); give the .zip a "
        "train run wrote, or leave out --policy for the committed one")


def _number(value: float) -> float | str:
    """A bound as JSON: a number, or "inf"/"-inf" (JSON has no infinities)."""
    return value if math.isfinite(value) else ("inf" if value > 0 else "-inf")


def _space_json(space: Any) -> dict[str, Any]:
    from gymnasium import spaces

    if not isinstance(space, spaces.Box):
        raise ValueError(f"only Box spaces can be saved, not {type(space).__name__}")
    return {"type": "Box", "shape": list(space.shape), "dtype": str(space.dtype),
            "low": [_number(float(v)) for v in space.low.ravel()],
            "high": [_number(float(v)) for v in space.high.ravel()]}


def _space(doc: Any, name: str) -> Any:
    from gymnasium import spaces

    if not isinstance(doc, dict) or doc.get("type") != "Box":
        raise ValueError(f"{name} is not a Box space")
    shape = tuple(doc["shape"])
    if not all(isinstance(n, int) and 0 < n <= 1 << 20 for n in shape):
        raise ValueError(f"{name} has the shape {shape}")
    if doc["dtype"] not in ("float32", "float64"):
        raise ValueError(f"{name} has the dtype {doc['dtype']!r}")
    dtype = np.dtype(doc["dtype"])
    bounds = []
    for key in ("low", "high"):
        values = doc[key]
        if not isinstance(values, list) or len(values) != math.prod(shape) or not all(
                isinstance(v, int | float) or v in ("inf", "-inf") for v in values):
            raise ValueError(f"{name}'s {key} is not {math.prod(shape)} numbers")
        bounds.append(np.array([float(v) for v in values], dtype).reshape(shape))
    return spaces.Box(bounds[0], bounds[1], shape, dtype)


def policy_metadata(policy: Any) -> dict[str, Any]:
    """The JSON that rebuilds ``policy`` (an SB3 ``ActorCriticPolicy`` with the default
    flatten features extractor and no gSDE)."""
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.common.torch_layers import FlattenExtractor

    params = policy._get_constructor_parameters()
    if type(policy) is not ActorCriticPolicy:
        raise ValueError(f"only an ActorCriticPolicy (MlpPolicy) can be saved, not "
                         f"{type(policy).__name__}")
    if params["use_sde"] or params["features_extractor_class"] is not FlattenExtractor:
        raise ValueError("a policy with gSDE or its own features extractor cannot be saved")
    activation = params["activation_fn"].__name__
    if activation not in ACTIVATIONS:
        raise ValueError(f"the activation {activation} is not one of {', '.join(ACTIVATIONS)}")
    net_arch = params["net_arch"]
    return {"format": FORMAT, "version": FORMAT_VERSION,
            "policy": "ActorCriticPolicy",
            "observation_space": _space_json(policy.observation_space),
            "action_space": _space_json(policy.action_space),
            "net_arch": (dict(net_arch) if isinstance(net_arch, dict) else list(net_arch)),
            "activation": activation,
            "share_features_extractor": bool(policy.share_features_extractor),
            "normalize_images": bool(policy.normalize_images),
            "log_std_init": float(params["log_std_init"])}


def save_policy(policy: Any, file: str | Path | IO[bytes]) -> None:
    """Write ``policy`` (an SB3 ``ActorCriticPolicy``, e.g. ``model.policy``) to ``file``
    in the format ``load_policy`` reads without unpickling."""
    import torch

    meta = policy_metadata(policy)
    weights = io.BytesIO()
    torch.save({k: v.detach().cpu() for k, v in policy.state_dict().items()}, weights)
    with zipfile.ZipFile(file, "w") as z:
        for name, content in ((META_ENTRY, json.dumps(meta, allow_nan=False).encode()),
                              (WEIGHTS_ENTRY, weights.getvalue())):
            # A fixed date: the same policy makes the same entries.
            entry = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
            z.writestr(entry, content, compress_type=zipfile.ZIP_DEFLATED)


def _read(z: zipfile.ZipFile, name: str, limit: int) -> bytes:
    if z.getinfo(name).file_size > limit:
        raise ValueError(f"its {name} is larger than {limit >> 20} MiB")
    return z.read(name)


def _pickled_entries(z: zipfile.ZipFile) -> str | None:
    """What of the zip is pickled (SB3's ``:serialized:`` data, pickle files), or None."""
    names = z.namelist()
    if "data" in names and b":serialized:" in _read(z, "data", MAX_WEIGHTS_BYTES):
        return "':serialized:' entries in its data, as stable-baselines3 saves them"
    pickles = [n for n in names if n.lower().endswith(PICKLE_SUFFIXES)]
    if pickles:
        return f"{', '.join(pickles[:3])}"
    return None


def _build(meta: Any, state: Any) -> Any:
    import torch
    from stable_baselines3.common.policies import ActorCriticPolicy

    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ValueError(f"its {META_ENTRY} is not a {FORMAT}")
    if meta.get("version") != FORMAT_VERSION:
        raise ValueError(f"its {META_ENTRY} is version {meta.get('version')!r}; this "
                         f"tfalda-sim reads version {FORMAT_VERSION}")
    if meta.get("policy") != "ActorCriticPolicy":
        raise ValueError(f"its policy class {meta.get('policy')!r} is not ActorCriticPolicy")
    activation = meta["activation"]
    if activation not in ACTIVATIONS:
        raise ValueError(f"the activation {activation!r} is not one of {', '.join(ACTIVATIONS)}")
    net_arch = meta["net_arch"]
    layers = (net_arch.values() if isinstance(net_arch, dict) else [net_arch])
    if not all(isinstance(x, list) and all(isinstance(n, int) and 0 < n <= 1 << 16
                                               for n in x) for x in layers):
        raise ValueError(f"its net_arch {str(net_arch)[:60]} is not lists of layer widths")
    if not isinstance(state, dict) or not all(
            isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in state.items()):
        raise ValueError(f"its {WEIGHTS_ENTRY} is not a state dict of tensors")
    policy = ActorCriticPolicy(
        _space(meta["observation_space"], "the observation space"),
        _space(meta["action_space"], "the action space"),
        lambda _: 0.0, net_arch=net_arch, activation_fn=getattr(torch.nn, activation),
        ortho_init=False, log_std_init=float(meta["log_std_init"]),
        share_features_extractor=bool(meta["share_features_extractor"]),
        normalize_images=bool(meta["normalize_images"]))
    policy.load_state_dict(state, strict=True)
    policy.set_training_mode(False)
    return policy


def load_policy(path: str | Path, *, trust: bool = False) -> Any:
    """The ``ActorCriticPolicy`` saved in ``path`` (``FileNotFoundError`` if there is none,
    ``PolicyFileError`` naming the file and why if it cannot be used). A file with pickled
    objects is refused (``UntrustedPolicyError``) unless ``trust``: then stable-baselines3
    loads it, running whatever its pickles hold."""
    import torch

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no policy file {path}; train one with `tfalda-sim train` "
                                "or use agents/policies/ppo.zip")
    try:
        with zipfile.ZipFile(path) as z:
            names = z.namelist()
            if trust and META_ENTRY not in names and "data" in names:
                return _load_sb3(path)
            pickled = _pickled_entries(z)
            if pickled is not None:
                raise UntrustedPolicyError(untrusted_message(path, pickled))
            if META_ENTRY not in names or WEIGHTS_ENTRY not in names:
                missing = [n for n in (META_ENTRY, WEIGHTS_ENTRY) if n not in names]
                raise _not_ours(path, f"it has no {' or '.join(missing)}")
            meta = json.loads(_read(z, META_ENTRY, MAX_META_BYTES))
            weights = _read(z, WEIGHTS_ENTRY, MAX_WEIGHTS_BYTES)
        try:
            state = torch.load(io.BytesIO(weights), map_location="cpu", weights_only=True)
        except Exception as exc:  # torch's UnpicklingError, RuntimeError, …
            if "weights_only" in str(exc) or "Unsupported global" in str(exc):
                raise UntrustedPolicyError(untrusted_message(
                    path, f"objects other than tensors in its {WEIGHTS_ENTRY}")) from None
            raise
        return _build(meta, state)
    except PolicyFileError:
        raise
    except (ImportError, MemoryError):  # no bad file: the CLI words them
        raise
    except zipfile.BadZipFile:
        raise _not_ours(path, "the file is not a zip file or is cut short") from None
    except OSError:  # no bad file: the CLI words them
        raise
    except Exception as exc:  # what the zip, JSON, torch readers and the build raise
        reason = str(exc).removeprefix("Error: ").strip().splitlines()
        raise _not_ours(path, reason[0] if reason else type(exc).__name__) from None


def _load_sb3(path: Path) -> Any:
    """A trusted stable-baselines3 save: SB3's loader, unpickling included."""
    from stable_baselines3 import PPO

    return PPO.load(path, device="cpu").policy
