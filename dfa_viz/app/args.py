"""The options of the feedback page: `dfa serve` (ServeArgs) and `dfa demo` (DemoArgs). Light
to import: nothing here loads torch, MuJoCo, rerun or viser.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

import tyro

from dfa_viz.configs import AdaptConfig


@dataclass(frozen=True)
class ServeArgs:
    """Serve the feedback web page: pick a task, demonstrate, diagnose, mark TI/TR, adapt.

    Binds 127.0.0.1 unless --host says otherwise; prints the URL. Every user action is appended
    to the session folder as JSON lines before the page acknowledges it; --session DIR resumes.
    """

    world: str = "nav2d"
    """The world the page opens on (any `dfa worlds` lists, or minigrid:ENV_ID)."""
    port: Annotated[int | None, tyro.conf.arg(metavar="INT")] = None
    """When left out, 8080 or the next free one; a port given must be free (0: any)."""
    host: str = "127.0.0.1"
    """The interface to bind; 0.0.0.0 exposes the page to the network."""
    session: Path | None = None
    """A session folder to resume (default: a new one under recordings/sessions/)."""
    policy: str | None = None
    """The policy to diagnose in --world instead of its base policy (as for `dfa run`)."""
    weights: Path | None = None
    """Finetuned weights dfa saved for --policy (as for `dfa run`)."""
    demos: Path | None = None
    """A LeRobotDataset folder whose episodes the page offers as demonstrations: those that
    start from the task's scene (every one, for a dataset that names no scenes)."""
    out: Path = Path("recordings")
    """Folder for the recordings and new sessions."""
    adapt: Annotated[AdaptConfig, tyro.conf.OmitArgPrefixes] = field(default_factory=AdaptConfig)
    """How "Augment & finetune" adapts (the finetuning experiment's defaults)."""


@dataclass(frozen=True)
class DemoArgs:
    """Open the feedback page on a default scenario, the diagnosis already computed.

    The failed rollout, the expert's demonstration and the counterfactual are ready to scrub;
    mark the edited concepts TI or TR and press "Augment & finetune". Ctrl-C stops the server.
    """

    world: str = "nav2d"
    """The world of the scenario."""
    shift: str = "distractor_ti"
    """The shift of the scenario."""
    seed: int = 0
    """The seed of the scenario."""
    port: Annotated[int | None, tyro.conf.arg(metavar="INT")] = None
    """When left out, 8080 or the next free one; a port given must be free (0: any)."""
    host: str = "127.0.0.1"
    """The interface to bind; 0.0.0.0 exposes the page to the network."""
    out: Path = Path("recordings")
    """Folder for the recordings and the session."""
    adapt: Annotated[AdaptConfig, tyro.conf.OmitArgPrefixes] = field(default_factory=AdaptConfig)
    """How "Augment & finetune" adapts (the finetuning experiment's defaults)."""
