"""graphloc: probabilistic localization of heterogeneous robot teams on GTSAM factor graphs.

Seeds (in ../shared/seeds/): 000 Feng et al. (mutual bearings + P3P for a climbing robot),
001 Breitenmoser et al. (four-marker targets), 003 (circle pose + EKF), 004 Kaushik et al.
(ground + ceiling laser map fusion). See docs/architecture.md for the data flow.
"""

__version__ = "0.1.0"
