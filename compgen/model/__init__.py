"""The machine as a chain of homogeneous transforms with every ISO 230 error of every axis:
the machine file's structure, the effect catalogue, the forward model and its Jacobian, the
axis lines, the paths, the nominal frames and the sides each pose reached its axes from."""
