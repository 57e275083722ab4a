"""volcl: a physically based volumetric path tracer on OpenCL."""
__version__ = "0.1.0"
