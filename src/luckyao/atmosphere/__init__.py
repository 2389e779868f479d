"""Layered frozen-flow von Karman turbulence: its statistics and its phase screens.

Public objects, by module --
statistics: Layer, R0Schedule, von_karman_psd, von_karman_covariance, von_karman_structure_function, r0_at_wavelength;
screens: StripSpec, strip_spec, strip_screen, ScreenSet.
"""
