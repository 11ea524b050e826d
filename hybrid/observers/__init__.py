"""What a run records and reports, read from the state and never changing it: the
trace's rows (`trace`), how each of its series is measured from the frames
(`metrics`), and the summary made of them (`summary`). `hybrid.run` drives them.
"""
