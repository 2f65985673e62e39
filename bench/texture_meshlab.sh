#!/usr/bin/env bash
# Issue 14: fresco's texture against MeshLab's texture filters on equal terms. For each
# synthetic scene (640x480, 24 views, no lens distortion: MeshLab's Bundler cameras would not
# carry it reliably) views 5 and 17 are held out; fresco texture and MeshLab's three filters
# (datasets/reference/meshlab_texture.py: param = parameterization + texturing from
# registered rasters, project = all rasters projected into the param filter's UVs,
# vertex = per-vertex colour from rasters) texture the ground-truth mesh from the other 22,
# and `fresco eval texture` scores every GLB with the same renderer and masks. Prints one line
# per scene and method (with the seam colour discrepancy of `fresco eval texture`) and writes datasets/reference/meshlab/texture_<scene>.json.
#   bench/texture_meshlab.sh                 torus, temple, blob at detail 2
#   SCENES="temple:2" bench/texture_meshlab.sh
#   NO_BUILD=1 KEEP=1 bench/texture_meshlab.sh
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ -z "${NO_BUILD:-}" ]]; then
    cargo build --release -p fresco
fi
PYTHON=${PYTHON:-$(bench/venv.sh texture)}
# pymeshlab's raster filters render depth with OpenGL: an X server (xvfb) with GLX and the
# xcb libraries Qt's platform plugin loads.
if ! command -v xvfb-run >/dev/null || ! ldconfig -p | grep -q libxcb-icccm.so.4; then
    apt-get install -y xvfb libxcb-icccm4 libxcb-keysyms1 libxcb-xinerama0 libxcb-image0 \
        libxcb-render-util0 libxkbcommon-x11-0 >/dev/null
fi
FRESCO=target/release/fresco
SCENES=${SCENES:-"torus:2 temple:2 blob:2"}
HELD=view_0005.png,view_0017.png
WORK=$(mktemp -d /tmp/atlas-meshlab.XXXXXX)
[[ -n "${KEEP:-}" ]] || trap 'rm -rf "$WORK"' EXIT
OUT=datasets/reference/meshlab
mkdir -p "$OUT"
echo "start $(date -u +%H:%M:%S) UTC, load: $(cut -d' ' -f1-3 /proc/loadavg)"
for s in $SCENES; do
    shape=${s%%:*}
    detail=${s##*:}
    d=$WORK/$shape
    $FRESCO synth "$shape" -o "$d" --detail "$detail" --distortion 0 --size 640x480 >/dev/null
    mesh=$d/mesh.ply
    t0=$(date +%s.%N)
    $FRESCO --json texture --colmap "$d/sparse" --images "$d/images" --mesh "$mesh" \
        --exclude "$HELD" --vertex-colors -o "$d/fresco" >"$d/fresco_summary.json"
    t1=$(date +%s.%N)
    xvfb-run -a -s "-screen 0 1280x1024x24 +extension GLX" "$PYTHON" datasets/reference/meshlab_texture.py --colmap "$d/sparse" \
        --images "$d/images" --mesh "$mesh" --exclude "$HELD" -o "$d/meshlab" >/dev/null
    for m in fresco/model.glb fresco/vertex_colors.glb meshlab/meshlab_param.glb \
        meshlab/meshlab_project.glb meshlab/meshlab_vertex.glb; do
        name=$(basename "$m" .glb)
        $FRESCO --json eval texture "$d/$m" --colmap "$d/sparse" --images "$d/images" \
            --views "$HELD" --masks "$d/masks" --save-renders "$d/renders_$name" >"$d/eval_$name.json"
    done
    "$PYTHON" - "$d" "$shape" "$detail" "$(echo "$t1 - $t0" | bc)" "$OUT" <<'PY'
import json, sys
from pathlib import Path
d, shape, detail, fresco_wall, out = Path(sys.argv[1]), sys.argv[2], sys.argv[3], float(sys.argv[4]), Path(sys.argv[5])
ml = json.loads((d / "meshlab" / "meshlab.json").read_text())
rows = {}
for name, label, secs in [("model", "fresco texture", fresco_wall),
                          ("vertex_colors", "fresco vertex colours", None),
                          ("meshlab_param", "MeshLab param+texture from rasters", ml["param"]["wall_s"]),
                          ("meshlab_project", "MeshLab rasters projected into its UVs", ml["project"]["wall_s"]),
                          ("meshlab_vertex", "MeshLab vertex colour from rasters", ml["vertex"]["wall_s"])]:
    e = json.loads((d / f"eval_{name}.json").read_text())
    rows[name] = {"label": label, "psnr": e["mean_psnr"], "psnr_gain": e["mean_psnr_gain"],
                  "ssim_gain": e["mean_ssim_gain"], "seconds": secs,
                  "seam_discrepancy": (e.get("seam_discrepancy") or {}).get("mean"),
                  "seam_length": (e.get("seam_discrepancy") or {}).get("seam_length"),
                  "per_view_psnr_gain": {k: v["psnr_gain"] for k, v in e["views"].items()}}
    t = f"{secs:6.1f} s" if secs is not None else "        "
    sd = rows[name]["seam_discrepancy"]
    seam = f"seams {sd:5.2f}/255 over {rows[name]['seam_length']:.2f}" if sd is not None else ""
    print(f"{shape} d{detail} {label:40} psnr {e['mean_psnr']:6.2f}  gain-fitted {e['mean_psnr_gain']:6.2f}  ssim {e['mean_ssim_gain']:.4f}  {t}  {seam}")
best = max(rows[k]["psnr_gain"] for k in ("meshlab_param", "meshlab_project", "meshlab_vertex"))
print(f"{shape} d{detail} fresco - best MeshLab filter: {rows['model']['psnr_gain'] - best:+.2f} dB (gain-fitted)")
(out / f"texture_{shape}.json").write_text(json.dumps({"scene": shape, "detail": int(detail), "size": "640x480",
    "held_out": ["view_0005.png", "view_0017.png"], "distortion": 0, "methods": rows,
    "fresco_minus_best_meshlab_db": rows["model"]["psnr_gain"] - best}, indent=1) + "\n")
PY
done
echo "end $(date -u +%H:%M:%S) UTC, load: $(cut -d' ' -f1-3 /proc/loadavg)"
