"""Run inside KiCad's own Python (the interpreter that can ``import pcbnew``), as a script:

    python3 kicad_tool.py plot    BOARD.kicad_pcb OUTDIR   fill zones, plot Gerbers and drill files
    python3 kicad_tool.py inspect BOARD.kicad_pcb          board facts as JSON on stdout
    python3 kicad_tool.py drc     BOARD.kicad_pcb REPORT   fill zones, run KiCad's DRC, JSON summary
    python3 kicad_tool.py footprint LIB.pretty NAME        a library footprint's pads as JSON

It imports nothing from magfab (KiCad's interpreter need not have magfab installed); magfab runs it
through :mod:`magfab.export.kicad`. Lengths in the JSON are millimetres.
"""

import json
import os
import re
import sys
from collections.abc import Callable

import pcbnew

LAYERS = [
    ("F.Cu", "F_Cu", "Top copper"), ("B.Cu", "B_Cu", "Bottom copper"), ("F.Paste", "F_Paste", "Top paste"),
    ("B.Paste", "B_Paste", "Bottom paste"), ("F.SilkS", "F_Silkscreen", "Top silkscreen"),
    ("B.SilkS", "B_Silkscreen", "Bottom silkscreen"), ("F.Mask", "F_Mask", "Top solder mask"),
    ("B.Mask", "B_Mask", "Bottom solder mask"), ("Edge.Cuts", "Edge_Cuts", "Board outline"),
]


def mm(v):
    return round(pcbnew.ToMM(v), 6)


def fill(board):
    pcbnew.ZONE_FILLER(board).Fill(board.Zones())


def plot(board_path, out_dir):
    board = pcbnew.LoadBoard(board_path)
    fill(board)
    pc = pcbnew.PLOT_CONTROLLER(board)
    po = pc.GetPlotOptions()
    po.SetOutputDirectory(out_dir)
    po.SetPlotFrameRef(False)
    po.SetUseGerberProtelExtensions(False)
    po.SetUseGerberX2format(True)
    po.SetIncludeGerberNetlistInfo(False)
    po.SetCreateGerberJobFile(False)
    po.SetSubtractMaskFromSilk(True)
    po.SetUseAuxOrigin(False)
    po.SetExcludeEdgeLayer(True)
    po.SetDrillMarksType(pcbnew.PCB_PLOT_PARAMS.NO_DRILL_SHAPE)
    written = []
    for name, suffix, desc in LAYERS:
        pc.SetLayer(board.GetLayerID(name))
        if not pc.OpenPlotfile(suffix, pcbnew.PLOT_FORMAT_GERBER, desc):
            raise SystemExit("KiCad could not open the plot file for " + name)
        if not pc.PlotLayer():
            raise SystemExit("KiCad could not plot " + name)
        written.append(pc.GetPlotFileName())
    pc.ClosePlot()
    drill = pcbnew.EXCELLON_WRITER(board)
    drill.SetOptions(False, False, pcbnew.wxPoint(0, 0), False)
    drill.SetFormat(True)
    drill.CreateDrillandMapFilesSet(out_dir, True, False)
    print(json.dumps(sorted(os.path.basename(p) for p in os.listdir(out_dir))))


def inspect(board_path):
    board = pcbnew.LoadBoard(board_path)
    fps = []
    for fp in board.GetFootprints():
        pads = []
        for p in fp.Pads():
            pos, size = p.GetPosition(), p.GetSize()
            pads.append({"number": p.GetNumber(), "x": mm(pos.x), "y": mm(pos.y), "w": mm(size.x), "h": mm(size.y),
                         "net": p.GetNetname(), "angle": p.GetOrientationDegrees(),
                         "layers": p.GetLayerSet().Seq().__len__()})
        pos = fp.GetPosition()
        fps.append({"ref": fp.GetReference(), "value": fp.GetValue(), "fpid": fp.GetFPIDAsString(),
                    "x": mm(pos.x), "y": mm(pos.y), "bottom": fp.IsFlipped(), "pads": pads})
    bbox = board.GetBoardEdgesBoundingBox()
    out = {
        "footprints": sorted(fps, key=lambda f: f["ref"]),
        "nets": sorted(str(n) for n in board.GetNetsByName().keys() if str(n)),  # noqa: SIM118 - a KiCad (SWIG) map, not a dict
        "tracks": sum(1 for t in board.GetTracks() if t.GetClass() == "PCB_TRACK"),
        "vias": sum(1 for t in board.GetTracks() if t.GetClass() == "PCB_VIA"),
        "zones": [{"net": z.GetNetname(), "layer": z.GetLayerName()} for z in board.Zones()],
        "outline": [mm(bbox.GetX()), mm(bbox.GetY()), mm(bbox.GetWidth()), mm(bbox.GetHeight())],
        "clearance": mm(board.GetDesignSettings().GetNetClasses().GetDefault().GetClearance()),
    }
    print(json.dumps(out, sort_keys=True))


def drc(board_path, report):
    board = pcbnew.LoadBoard(board_path)
    fill(board)
    ok = pcbnew.WriteDRCReport(board, report, pcbnew.EDA_UNITS_MILLIMETRES, True)
    with open(report, encoding="utf-8") as f:
        text = f.read()
    counts = {}
    for key in ("violations", "unconnected pads", "footprint errors"):
        pattern = r"\*\* Found (\d+) DRC " + key if key == "violations" else r"\*\* Found (\d+) " + key
        m = re.search(pattern, text, re.IGNORECASE)
        counts[key] = int(m.group(1)) if m else None
    print(json.dumps({"ok": bool(ok), "counts": counts}))


def footprint(lib, name):
    fp = pcbnew.FootprintLoad(lib, name)
    if fp is None:
        raise SystemExit("no footprint " + name + " in " + lib)
    pads = []
    for p in fp.Pads():
        pos, size = p.GetPosition(), p.GetSize()
        pads.append({"number": p.GetNumber(), "x": mm(pos.x), "y": mm(pos.y), "w": mm(size.x), "h": mm(size.y),
                     "shape": p.GetShape(), "layers": [pcbnew.LayerName(layer) for layer in p.GetLayerSet().Seq()]})
    print(json.dumps({"name": fp.GetFPID().GetLibItemName().wx_str(), "pads": pads}, sort_keys=True))


if __name__ == "__main__":
    command, args = sys.argv[1], sys.argv[2:]
    commands: dict[str, Callable[..., None]] = {"plot": plot, "inspect": inspect, "drc": drc, "footprint": footprint}
    commands[command](*args)
