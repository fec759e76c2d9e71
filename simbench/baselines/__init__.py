"""Competitor sensors of the paper's Table 3 and Fig. 9, simulated the way the devices work:
a Kinect-v1-like speckle structured-light sensor (:mod:`simbench.baselines.kinect`) and an
SR4000-like continuous-wave time-of-flight camera (:mod:`simbench.baselines.tof`)."""
