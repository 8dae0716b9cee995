"""Reading JSON documents with errors that name the file: `tracking.jsonfile.read_json`, which tracking (the
lowest layer) uses for its own files too; here so that arapp's formats find it beside them."""

from tracking.jsonfile import read_json

__all__ = ["read_json"]
