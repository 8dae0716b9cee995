"""`arapp model`: inspect a model file or export it as a printable, watertight mesh."""

HELP = "inspect a NURBS model (info) or export it as a watertight printable mesh (export)"


def add_arguments(parser):
    sub = parser.add_subparsers(dest="model_command", metavar="ACTION", required=True)
    info = sub.add_parser("info", help="surfaces, degrees, domains, bounding box, triangle count",
                          description="Print the surfaces, degrees, domains, bounding box and the "
                          "triangle count at default quality of a model file (.json or a mesh).")
    info.add_argument("path", help="model file: .json (arapp model) or .stl/.obj/.ply/.3mf/.glb, or a library "
                      "model's name (vase)")
    export = sub.add_parser("export", help="write a watertight solid in millimetres",
                            description="Write the model as a watertight solid in millimetres, scaled "
                            "to its placement size (or --size), open surfaces thickened.")
    export.add_argument("path", help="model file (.json or a mesh), or a library model's name (vase)")
    export.add_argument("-o", "--output", required=True, metavar="OUT",
                        help="output file: .stl, .obj, .ply, .3mf or .glb")
    export.add_argument("--thickness", type=float, default=2.0, metavar="MM",
                        help="wall thickness for open surfaces, mm (default 2)")
    export.add_argument("--size", type=float, default=None, metavar="MM",
                        help="largest extent of the printed part, mm (default: the model's placement size)")
    export.add_argument("--tolerance", type=float, default=None, metavar="T",
                        help="chord tolerance of the tessellation, mm (default: size / 500)")


def _fmt_range(lo, hi):
    return f"[{lo:.6g}, {hi:.6g}]"


def run(args) -> int:
    from arapp.geometry import load_model
    from arapp.geometry.library import model_path

    model = load_model(args.path)
    if args.model_command == "info":
        print(f"model: {model.name}")
        print(f"file: {model_path(args.path)}")
        print(f"units: {model.units}")
        print("color: " + ", ".join(f"{c:.3g}" for c in model.color))
        pl = model.placement
        print(f"placement: size {pl.size_mm:g} mm, offset {list(pl.offset)} mm, rotation {list(pl.rotation_deg)} deg")
        for i, s in enumerate(model.surfaces):
            (u0, u1), (v0, v1) = s.domain
            kind = "rational" if s.is_rational else "non-rational"
            print(f"surface {i}: degree ({s.degree_u}, {s.degree_v}), control net {s.shape[0]} x {s.shape[1]}, "
                  f"{kind}, domain u {_fmt_range(u0, u1)} v {_fmt_range(v0, v1)}")
        lo, hi = model.bounds()
        print(f"bounding box ({model.units}): min {[round(float(x), 6) for x in lo]} max {[round(float(x), 6) for x in hi]}")
        print(f"triangles at default quality: {len(model.mesh().faces)}")
        return 0
    mesh = model.export(args.output, size_mm=args.size, thickness_mm=args.thickness, tolerance_mm=args.tolerance)
    ext = mesh.extents
    print(f"wrote {args.output}: {len(mesh.faces)} triangles, watertight {mesh.is_watertight}, "
          f"volume {mesh.volume:.1f} mm^3, size {ext[0]:.1f} x {ext[1]:.1f} x {ext[2]:.1f} mm")
    return 0
