"""Dancing to music as it plays: live input, online beats, on-the-fly choreography, a viewer.

Submodules are imported on demand: the web viewer (`quaddance.live.viewer`) pulls in viser,
which takes seconds to import, so nothing here imports it.
"""
