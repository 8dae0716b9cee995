"""`aruco`: one square ArUco marker; frame centred on it, x right, y up, z out of the paper."""

from __future__ import annotations

from tracking.anchors.kinds.base import AnchorKind, mm, square_corners


class ArucoKind(AnchorKind):
    """A single marker `id` of `dictionary`, side `length` (black border included)."""

    name = "aruco"
    required = {"dictionary": str, "id": int, "length": float}
    positive = ("length",)
    single_square = True
    cli_name = "aruco"

    def marker_ids(self, spec):
        return [spec.id]

    def geometry(self, spec):
        return {int(spec.id): square_corners(spec.length)}, None, None

    def describe(self, spec):
        return f"ArUco id {spec.id}, {spec.dictionary}, {mm(spec.length)}"

    def caption(self, spec):
        return f"ArUco {spec.dictionary} id {spec.id}, side {mm(spec.length)}"

    def file_stem(self, spec):
        return f"aruco_{spec.dictionary}_id{spec.id}_{spec.length * 1000:g}mm"

    def cli_block(self, args):
        return {"kind": "aruco", "dictionary": args.dictionary, "id": args.id, "length": args.length}
