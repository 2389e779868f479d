"""Reading and writing results: netCDF datasets with provenance, FITS images, config hashing."""
