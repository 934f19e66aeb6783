"""2D navigation: a white agent goes to a coloured, shaped goal, maybe past a distractor."""
