"""The recording format `arapp-recording/1` (docs/recording-format.md): the session.json schema (`schema`),
the writer (`writer`) and the depth stream (`depth_stream`). The reader is a source: tracking.sources.recording.
"""
