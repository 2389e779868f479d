"""The workflow's steps: the time loop and every cached product it uses (screens, WFS
calibration, reconstructor and command matrix, LGS slopes), and the lucky post-processing."""
