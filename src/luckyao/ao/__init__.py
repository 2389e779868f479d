"""Adaptive-optics correction: the deformable mirror, open-loop command matrices and the
correction applied in the time loop (LTAO, GLAO; tip-tilt left alone).

Public objects, by module --
dm: DeformableMirror; control: command_matrix, dm_slopes_matrix, ground_layers;
correction: OpenLoopCorrection, DelayedDm.
"""
