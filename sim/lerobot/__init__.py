"""LeRobotDataset v3.0, the dataset format of LeRobot, written and read without LeRobot.

    format.py    where each part of a dataset folder lives, the features and tables' schemas
    stats.py     meta/stats.json and each episode's stats, computed as LeRobot computes them
    video.py     video features through PyAV (AV1, as LeRobot encodes them)
    episode.py   Episode: T frames, each an observation and the action taken from it
    writer.py    write_dataset(root, episodes, fps=, robot_type=, video=) -> Written
    reader.py    Dataset(root): info, tasks, episodes; .episode(n) -> Episode
    demo.py      a dataset's episode as a demonstration of a task (`--demo lerobot:DIR`)

Imports pyarrow (and PyAV for videos) when used; `import sim` does not import this package.
"""

from sim.lerobot.episode import Episode
from sim.lerobot.reader import Dataset
from sim.lerobot.writer import CAMERA, Written, write_dataset

__all__ = ["CAMERA", "Dataset", "Episode", "Written", "write_dataset"]
