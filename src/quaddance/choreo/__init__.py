"""Human-style dance as left/right foot heights: from a beat grid or from a motion file.

`grid` says what the choreographer needs from music, `choreographer` is the built-in dancer,
and the motion importers turn human motion files into the same foot-height curves. Nothing
here imports librosa, so targets can be built where no audio stack exists.
"""
