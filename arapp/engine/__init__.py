"""The frame engine: a source's frames through tracking and drawing to a composited picture, headless (no Qt).

Sources and their cameras (`sourcespec`, `input_source`), the pipeline (`pipeline`: tracker + renderer),
the live engine's threads (`player` -> `slots` -> `processor`, joined by `live`) steered by `commands`,
its stages (anchor `discovery`, print-preview `toolpaths`, `recording`, AR video `capture`), the headless
replay (`replay`) and its host for tests (`headless`). Imports printing, render, scan, geometry, store and
tracking; never the app model or the GUI (docs/architecture.md).
"""
