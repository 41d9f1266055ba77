"""Benchmark of inter-robot scan registration on `dual-robot-room` (issue 7, seed 004 Sec. IV-V).

Over random placements and headings of the two robots (one scenario seed each), per room
variant, in one run, three ways to get T_G0_C0 (first ceiling scan in the first ground scan):
  icp_no_guess   point-to-plane ICP from the identity (seed 004 Fig. 5: fails on inverted scans)
  fpfh_ransac    Open3D FPFH + RANSAC global registration, then the same ICP
  graphloc       P3P on the LEDs + HypothesisTracker over the ceiling robot's motion -> the same
                 ICP -> factor graph (graphloc.pipelines.map_fusion.fuse, map building skipped)
All three share the denoised clouds and the ICP settings. Success: rotation error < 2 deg and
translation error < 5 cm. Wall time per method = its initial guess + ICP (+ graph for graphloc);
KISS-ICP odometry (needed by graphloc's guess, and by every method to build the local maps)
is reported separately.

    .venv/bin/python scripts/bench_fusion.py --out out/bench_fusion            # 50 x 4 variants
    .venv/bin/python scripts/bench_fusion.py --quick --out out/bench_fusion_quick

`--real` runs issue 16's protocol on the real indoor fragment (tests/data/real_room) instead:
per overlap (about 60% and 30%, graphloc.experiments.real_views) and trial, one ground + one
flipped ceiling view (independent 50% subsampling, 5 mm noise, ceiling sensor 2.5 m up with a
random yaw), then the pose hint perturbed by exactly 3 deg / 5 cm and by 10 deg / 20 cm (the
hint's 1-sigma given to graphloc is that perturbation). Methods on the same prepared clouds:
  graphloc        fuse (robust_register + acceptance checks + graph), what fuse-maps --hint runs
  graphloc_before fuse with robust=False: the coarse-to-fine refine of before issue 16
  o3d_icp         Open3D point-to-plane ICP from the hint (one scale; correspondences within
                  sigma_t + sigma_rot * median range, at least the fine distance)
  o3d_icp_fine    the same within the fine distance (RegistrationConfig.max_correspondence[-1])
  fpfh_ransac     Open3D FPFH + RANSAC (no hint), then point-to-plane ICP at the fine distance
Success: rotation error < 1 deg and translation < 5 cm and, for graphloc, accepted. A false
accept is a result returned as fused with a larger error (the Open3D paths accept everything).
NEES of graphloc's accepted results against the chi-square 95% band of their mean.

    .venv/bin/python scripts/bench_fusion.py --real --trials 20 --out out/bench_fusion_real \
        --doc docs/results_fusion_real.md

`--real --calibrate` fits the calibration of graphloc's registration covariance (scale and
floor, `graphloc.mapping.registration_covariance.calibrated_covariance`) by maximum likelihood
on view pairs of other seeds than the benchmark's, and writes docs/results_fusion_calibration.json
(RegistrationConfig's defaults are that fit; tests/test_fusion_real.py checks they agree):

    .venv/bin/python scripts/bench_fusion.py --real --calibrate --trials 20 --seed 1000
"""

import os
import sys

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one process per core; set before Open3D loads

from graphloc.experiments.fusion_bench import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
