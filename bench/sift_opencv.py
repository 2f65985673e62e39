"""OpenCV SIFT over a folder of photos, for bench/sift.sh: prints JSON {images, keypoints, seconds}.

Each photo is read (cv2.imread, colour), converted to grey (Rec. 601, as fresco) and passed to
cv2.SIFT_create().detectAndCompute with OpenCV's default thread settings; the time covers
reading, conversion and detection+description of every photo, as fresco's summary does.

`sift_opencv.py --image <photo> [threads]`: one photo, decoding and grey conversion untimed, one untimed
warm-up call, then one timed detectAndCompute; prints JSON {keypoints, seconds}.
"""
import json
import os
import sys
import time

import cv2

if sys.argv[1] == "--image":
    if len(sys.argv) > 3:  # optional thread count (bench/sift.sh's one-thread table)
        cv2.setNumThreads(int(sys.argv[3]))
    grey = cv2.cvtColor(cv2.imread(sys.argv[2], cv2.IMREAD_COLOR), cv2.COLOR_BGR2GRAY)
    sift = cv2.SIFT_create()
    sift.detectAndCompute(grey, None)
    t0 = time.perf_counter()
    kps, desc = sift.detectAndCompute(grey, None)
    seconds = time.perf_counter() - t0
    print(json.dumps({"keypoints": len(kps), "seconds": seconds, "threads": cv2.getNumThreads()}))
    sys.exit(0)

folder = sys.argv[1]
names = sorted(n for n in os.listdir(folder) if n.lower().endswith((".png", ".jpg", ".jpeg")))
t0 = time.perf_counter()
sift = cv2.SIFT_create()
total = 0
for n in names:
    bgr = cv2.imread(os.path.join(folder, n), cv2.IMREAD_COLOR)
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    kps, desc = sift.detectAndCompute(grey, None)
    total += len(kps)
seconds = time.perf_counter() - t0
print(json.dumps({"images": len(names), "keypoints": total, "seconds": seconds,
                  "threads": cv2.getNumThreads(), "opencv": cv2.__version__}))
