#!/usr/bin/env bash
# Offscreen frame sequences of species drying from summer to dry (docs/sequences/), with a
# contact sheet per species.  Usage: bash tools/sequences.sh [species ...]
set -euo pipefail
cd "$(dirname "$0")/.."
species=${*:-maple oak chestnut}
for s in $species; do
  rm -rf "docs/sequences/$s"
  .venv/bin/leafsim run --species "$s" --frames 3000 --every 500 --out "docs/sequences/$s" \
      --set colour.age_rate=0.3 --stats "docs/sequences/$s.stats.jsonl" --json > "docs/sequences/$s.json"
  rm -f "docs/sequences/$s/final.npz"
  .venv/bin/python - "$s" <<'PY'
import sys, glob, cv2, numpy as np
s = sys.argv[1]
frames = sorted(glob.glob(f"docs/sequences/{s}/frame_*.png"))
ims = [cv2.resize(cv2.imread(f), (320, 240), interpolation=cv2.INTER_AREA) for f in frames]
for f, im in zip(frames, ims):
    cv2.putText(im, f.split("_")[-1][:-4], (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (40, 40, 40), 1, cv2.LINE_AA)
cv2.imwrite(f"docs/sequences/{s}_sheet.png", np.hstack(ims))
PY
done
