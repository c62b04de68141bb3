"""``raf field``: inspect the competition map, draw it, or dump it as JSON."""
from __future__ import annotations

import argparse
import json

NAME = "field"
HELP = "show the competition map: a summary, a top-view PNG (--png) or every marker as JSON (--json)"
ORDER = 10


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--png", metavar="FILE", help="draw a top view of the field into FILE")
    parser.add_argument("--json", action="store_true", help="print every marker (id, kind, size, pose, corners)")
    parser.add_argument("--list", action="store_true", help="list the shipped field names")


def run(args) -> int:
    from ..field import available_fields, load_field

    if args.list:
        print("\n".join(available_fields()))
        return 0
    field = load_field(args.field)
    if args.json:
        print(json.dumps([{"id": m.id, "kind": m.kind, "size": m.size, "position": m.position.round(6).tolist(),
                           "quat_xyzw": m.quaternion_xyzw.round(6).tolist(), "corners": m.corners.round(6).tolist()}
                          for m in field.markers], indent=1))
        return 0
    if args.png:
        from ..field.draw import save_field_png

        print(f"wrote {save_field_png(field, args.png)}")
        return 0
    print(f"field {field.name}: {field.description}")
    print(f"  floor x {field.floor.x}, y {field.floor.y}")
    print(f"  markers: {len(field.floor_markers())} floor, {len(field.wall_markers())} wall "
          f"(sizes {sorted({m.size for m in field.markers})} m), dictionary {field.dictionary}")
    print(f"  walls and ribs: {len(field.boxes)}; slots: {len(field.slots)}; team areas: {len(field.team_areas)}")
    sp = field.start_pose
    print(f"  start pose: x {sp.x}, y {sp.y}, heading {sp.theta:.4f} rad")
    return 0
