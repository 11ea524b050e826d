"""Pictures of a run: the frames they are drawn from (`frames`: a recording's or a
scene's), the paper's figure 4 (`figure`), the MP4 (`video`), MuJoCo's live viewer
(`live`) and the run's time-series figure (`run_figure`, also a process of its own).
`hybrid.render` is the command and the names' public home."""
