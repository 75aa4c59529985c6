"""An interactive 3-D viewer of episodes, live and recorded, in any browser.

* Live: ``tether-gym-view --env ID --controller NAME [NAME2] [--seed S]`` (or ``python -m
  tether_gym.view``) steps the env with the controller(s) and serves the view on 127.0.0.1,
  paced by the page's clock; two controllers run the same seed side by side.
* Recorded: :func:`record_episode` and :func:`save_recording` write an episode as ``.npz`` data
  (``agents.compare`` and ``agents.benchmark`` do with ``--save-episodes``); ``--recording A.npz
  [B.npz]`` plays them back on one time slider.
* Shared: ``--export episode.html`` (:func:`export_html`) writes a self-contained page that opens
  offline, with no server.

The view draws satellites by role (with thrusters, passive, tether beads), cables coloured by
tension with slack cables dashed and broken ones marked, thrust arrows, the frame's name, the
time, and the vibration energy and reward as small plots synced to the scene. It has play, pause,
speed and step controls, a time slider, orbit, zoom and pan, and an exaggeration slider for the
centimetre vibrations of 100 m cables.

Why three.js, in a page of our own. The candidates were viser, rerun-sdk, meshcat, plotly and
three.js. The export has to be a single file that works offline, and the live view has to run on
a training machine reached through an SSH tunnel; one page serving all three uses keeps one
drawing code for them. three.js is the most widely used WebGL library (MIT, released monthly,
with orbit controls, dashed lines and arrows built in), and bundled once with esbuild
(``scripts/build_viewer.sh``) it makes a 0.6 MB script that the package inlines into every page,
so users need no Node.js and the Python side needs only the standard library. viser serves
a fine live scene from Python, but its recordings play back only in its client app served over
HTTP, not as one offline file, and it adds a websocket server and its dependencies; rerun's
viewer is a large WebAssembly application with its own recording format; meshcat's development
has slowed and its animations are keyframes without synced plots; plotly writes offline HTML,
but its 3-D animation redraws whole figures (a few frames per second for hundreds of frames) and
cannot exaggerate displacements in the browser.
"""

from tether_gym.viewer.page import export_html
from tether_gym.viewer.recording import (
    FORMAT,
    FORMAT_VERSION,
    EpisodeRecording,
    EpisodeStepper,
    RecordingError,
    load_recording,
    record_episode,
    recording_file_name,
    save_recording,
)
from tether_gym.viewer.server import LiveSession, ViewerError, ViewerServer

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "EpisodeRecording",
    "EpisodeStepper",
    "LiveSession",
    "RecordingError",
    "ViewerError",
    "ViewerServer",
    "export_html",
    "load_recording",
    "record_episode",
    "recording_file_name",
    "save_recording",
]
