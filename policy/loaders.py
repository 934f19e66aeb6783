"""The registry of policy loaders: every prefix `--policy PREFIX:...` accepts, and the function
that loads a policy of that kind.

    register_policy_loader(prefix, loader)   add a loader (a callable, or "module:function");
                                             a prefix another loader holds is a UserError
    loader_prefixes()                        every registered prefix, the built-in ones first
    load_with(prefix, target, world)         the policy "PREFIX:TARGET" names, checked on one of
                                             the world's frames
    unknown(spec)                            the one line for a prefix no loader holds

A loader is `loader(target: str, world) -> policy.model.Policy`: `target` is the spec after
"PREFIX:" as the user typed it, and the policy gives (B, world.action_dim) outputs for the
world's uint8 (B, H, W, 3) frames. It sets the policy's `origin` (`Origin.of_file(prefix,
path)`: the file it read, which recordings name and a finetuned copy records instead of any
code; required), its `source` (the spec, naming its files by absolute paths; the spec as typed
when unset) and, when the policy's own format can hold a finetuned copy, `save_beside`.
Anything wrong with the user's files is a one-line UserError.

Loaders come from three places besides the built-in ones (`onnx`, `torch`, `sb3`, registered
below by "module:function", so that nothing is imported until a spec asks for it): installed
packages that declare an entry point in the group "dfa.policies" (prefix = "module:function"),
read on first use; the environment variable DFA_POLICIES, a comma-separated list of
"prefix=module:function", read on first use (and again when it changes); and
register_policy_loader called by code that runs before the command (a module is imported from
the Python path, as `torch:` imports one). Only these name code: a checkpoint folder never
names a loader (its config.json is data), and nothing is unpickled. Whatever a loader from
outside raises (SystemExit included), or a policy it gives that is not a Policy, is one line.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import os
import re
import threading
from collections.abc import Callable

from policy.model import Origin, Policy
from policy.obs import ObsSpec, said
from sim.core import UserError
from sim.registry import callable_name

ENTRY_POINTS = "dfa.policies"
ENV_LIST = "DFA_POLICIES"
PREFIX = re.compile(r"^[A-Za-z][A-Za-z0-9_-]*$")  # what a prefix may be: no path looks like one
SPEC = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")  # "package.module:function"
Loader = Callable | str

BUILT_IN = ("onnx", "torch", "sb3")  # the project's loaders: policy.<prefix>_policy:load
_loaders: dict[str, Loader] = {}
_lock = threading.RLock()
_entry_points_read = False
_env_read = ""  # the value of DFA_POLICIES last read


def register_policy_loader(prefix: str, loader: Loader) -> None:
    """Register `loader` for specs "PREFIX:..." (a callable, or "module:function", imported
    when a spec first asks for it). Registering the same loader again changes nothing; a prefix
    another loader holds is a UserError (nothing is replaced)."""
    if not isinstance(prefix, str) or not PREFIX.match(prefix):
        raise UserError(
            f"a policy loader's prefix is a letter then letters, digits, '_' or '-', not "
            f"{str(prefix)[:40]!r}"
        )
    if isinstance(loader, str) and not SPEC.match(loader):
        raise UserError(f"policy loader {prefix}: {loader[:80]!r} is not module:function")
    if not isinstance(loader, str) and not callable(loader):
        raise UserError(f"policy loader {prefix}: a {type(loader).__name__} is not callable")
    with _lock:
        old = _loaders.get(prefix)
        if old is not None and old != loader:
            raise UserError(
                f"a policy loader for {prefix}: is already registered ({callable_name(old)}); "
                f"register {callable_name(loader)} under another prefix"
            )
        _loaders[prefix] = loader


for _prefix in BUILT_IN:
    register_policy_loader(_prefix, f"policy.{_prefix}_policy:load")


def _read_outside() -> None:
    """Entry points (once) and DFA_POLICIES (whenever it changes) into the registry."""
    global _entry_points_read, _env_read
    with _lock:
        if not _entry_points_read:
            _entry_points_read = True
            for ep in importlib.metadata.entry_points(group=ENTRY_POINTS):
                if ep.name in _loaders and _loaders[ep.name] != ep.value:
                    dist = getattr(ep.dist, "name", "a package")
                    raise UserError(
                        f"the {ENTRY_POINTS} entry point {ep.name} = {ep.value} of {dist} names "
                        "a prefix already registered "
                        f"({callable_name(_loaders[ep.name])}); rename it"
                    )
                register_policy_loader(ep.name, ep.value)
        listed = os.environ.get(ENV_LIST, "")
        if listed != _env_read:
            _env_read = listed
            for item in filter(None, (s.strip() for s in listed.split(","))):
                prefix, eq, loader = (s.strip() for s in item.partition("="))
                if not eq:
                    raise UserError(f"{ENV_LIST}: {item[:80]!r} is not prefix=module:function")
                try:
                    register_policy_loader(prefix, loader)
                except UserError as e:
                    raise UserError(f"{ENV_LIST}: {e}") from None


def loader_prefixes() -> tuple[str, ...]:
    """Every registered prefix, the built-in ones first."""
    _read_outside()
    with _lock:
        return tuple(_loaders)


def is_registered(prefix: str) -> bool:
    _read_outside()
    with _lock:
        return prefix in _loaders


def unknown(spec: str) -> UserError:
    """The one line for a spec "PREFIX:..." whose prefix no loader holds."""
    prefix = spec.partition(":")[0]
    kinds = ", ".join(f"{p}:..." for p in loader_prefixes())
    return UserError(
        f"{spec[:80]}: no policy loader for {prefix[:40]}:; accepted: DIR (a checkpoint "
        f"folder), {kinds}"
    )


def _resolve(prefix: str) -> Callable:
    with _lock:
        loader = _loaders[prefix]
    outside = prefix not in BUILT_IN
    if callable(loader):
        return loader
    module, function = loader.split(":")
    try:
        target = importlib.import_module(module)
        for part in function.split("."):
            target = getattr(target, part)
    except ModuleNotFoundError as e:
        if not outside:
            raise
        raise UserError(
            f"{prefix}: its loader {loader}: no module {e.name!r} on the Python path (add its "
            "folder to PYTHONPATH)"
        ) from None
    except AttributeError:
        if not outside:
            raise
        raise UserError(
            f"{prefix}: its loader {loader}: module {module} has no {function}"
        ) from None
    except (Exception, SystemExit) as e:
        if not outside:
            raise
        raise UserError(f"{prefix}: importing its loader {loader} raised {said(e)}") from None
    if not callable(target):
        raise UserError(
            f"{prefix}: its loader {loader} is a {type(target).__name__}, not a function"
        )
    return target


def load_with(prefix: str, target: str, world):
    """The policy "PREFIX:TARGET" names for `world`, checked on one of its frames; a loader
    from outside that raises, or gives anything but a Policy, is one line."""
    if not is_registered(prefix):
        raise unknown(f"{prefix}:{target}")
    load = _resolve(prefix)
    outside = prefix not in BUILT_IN
    try:
        policy = load(target, world)
    except UserError:
        raise
    except (Exception, SystemExit) as e:
        if not outside:
            raise
        raise UserError(f"{prefix}:{target[:80]}: its loader raised {said(e)}") from None
    if not isinstance(policy, Policy):
        raise UserError(
            f"{prefix}:{target[:80]}: its loader gave a {type(policy).__name__}, not a "
            "policy.model.Policy"
        )
    if not isinstance(policy.origin, Origin):
        raise UserError(
            f"{prefix}:{target[:80]}: its loader recorded no origin (policy.model.Origin: the "
            "file it read), which recordings and finetuned copies name"
        )
    if policy.source is None:
        policy.source = f"{prefix}:{target}"
    return probe(policy, world)


def probe(policy, world):
    """Run the policy on one of the world's frames: a wrong input or output shape is one line."""
    frame = world.render(world.sample_scene(0))[None]  # (1, H, W, 3)
    try:
        out = policy.outputs(frame)
    except UserError:
        raise
    except Exception as e:  # the module's own complaint about its input
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        obs = getattr(policy, "obs", None) or getattr(policy.net, "obs", None) or ObsSpec()
        raise UserError(
            f"the policy does not take {world.name}'s frames {tuple(world.obs_shape)} "
            f"converted to {obs.shape(world.obs_shape)}: {first[:160]}"
        ) from None
    if out.shape != (1, world.action_dim):
        what = "action scores" if world.discrete else "action components"
        raise UserError(
            f"the policy gives outputs of shape {tuple(out.shape[1:])} per frame, but "
            f"{world.name} needs {world.action_dim} {what}"
        )
    return policy
