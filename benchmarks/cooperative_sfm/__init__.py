"""Cooperative motion and structure from one camera with a teammate robot as the scale anchor
(seed 003, 003_8db27855ce2d5f68.txt: section II "robot tracker" gives the
3D position of the teammate's base centre from its ellipse, II-B the motion estimator tracks
KLT features; the robots move and stop in turns) as ONE factor graph solved by `Session`
(batch Levenberg-Marquardt or online iSAM2, same factors):

  x(0,t)  camera pose of the moving robot at frame t (Pose3, world = camera 0, OpenCV axes)
  x(1,t)  the teammate's base disk at frame t (Pose3: origin = centre, z = disk normal), for
          the frames it is seen (Point3 centre in the 'moment_matched_centre' baseline)
  l(j)    KLT feature j (Point3)

  PriorFactorPose3 on x(0,0)                 seed III: the robot starts at the origin (zero
                                             initial covariance of T and omega)
  BetweenFactorPose3 x(0,t-1) -> x(0,t)      seed eq. 8 with F = identity: constant-position
                                             motion model with the process noise Q
  GenericProjectionFactorCal3_S2 x(0,t), l(j)  seed eq. 14: KLT pixels (Huber kernel)
  max-mixture of BetweenFactorPose3          seed eqs. 1-4: the two circle poses T_cam_base of the
    x(0,t) -> x(1,t), one per candidate      sighting (centre + normal; yaw about the normal loose),
                                             Olson & Agarwal max-mixture (factors.mixture), weights
                                             from the candidate scores
  AttitudeFactorPose3 on x(1,t)              the teammate stands on the ground: base y axis up
                                             (one per stance)
  BetweenFactorPose3 x(1,s) -> x(1,t)        the teammate stood still (zero motion)
  RangeFactorPose3 x(1,s) -> x(1,t)          the teammate moved (straight) by its odometry distance
  PriorFactorPoint3 on l(j)                  seed III: KLT points start "all at the same
                                             position" with a high covariance -- here on their
                                             first ray at one common depth, std
                                             feature_prior_sigma (the EKF's initial state)

Every KLT track becomes a landmark at its first observation, so rotation is constrained from
the first frames on and no landmark is ever undetermined (a point pushed behind a camera by an
undamped iSAM2 step, where GenericProjectionFactor gives no information, keeps its prior;
without the prior iSAM2 raised IndeterminantLinearSystem on crawler-pair). Projection factors
with explicit landmarks rather than SmartProjectionPose3Factor: a smart factor grows with its
track, and Session (append-only `add`) cannot tell iSAM2 that an added factor changed. Batch
and online see the same factors, added frame by frame through one `Session`.

The circle front-end (`graphloc.vision.circle`) returns BOTH poses of the base (the ellipse
cannot tell them apart). Their centres nearly coincide but their normals differ widely (the
front-end table of docs/results_seed003.md measures both; the false normal also tilts out of
the vertical plane and drifts as the robots move). Both enter as a max-mixture: the genuine
candidate is the one consistent with the other sightings (tied by the teammate's zero-motion
factors) and with its upright attitude, so the graph picks it per frame
(`CooperativeSfm.active_components`, `SfmRun.active_final` / `active_causal`) and the normal
constrains the camera attitude too. In online mode the choice is re-evaluated only when iSAM2
relinearizes x(0,t) or x(1,t) (see `factors.mixture.MaxMixture`); the session default
relinearize_threshold 0.01 with two extra updates per frame. The moment-matched Gaussian of the
candidate centres on a Point3 (normals unused) stays as the baseline
teammate_model='moment_matched_centre'. A Python CustomFactor cannot be pickled by GTSAM, so
`Session.save` works only for that baseline.
"""

from benchmarks.cooperative_sfm.config import TEAMMATE_MODELS, CooperativeSfmConfig
from benchmarks.cooperative_sfm.graph import CooperativeSfm
from benchmarks.cooperative_sfm.run import SfmRun, run_cooperative_sfm

__all__ = [
    "TEAMMATE_MODELS",
    "CooperativeSfm",
    "CooperativeSfmConfig",
    "SfmRun",
    "run_cooperative_sfm",
]
