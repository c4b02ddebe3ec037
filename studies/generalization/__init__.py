"""The generalization suite: baseline, fixed and adaptive on worlds the surrogate never trained
on (``suite``: which worlds; ``run``: scoring them with the pipeline's own code; ``summary``:
ratios, median, worst world, win rate, bootstrap interval; ``report``: the stage's outputs)."""
