"""Pictures of a run: the frames they are drawn from (`frames`: a recording's or a
scene's), the paper's figure 4 (`figure`), the MP4 (`video`) and MuJoCo's live viewer
(`live`). `hybrid.render` is the command and the names' public home."""
