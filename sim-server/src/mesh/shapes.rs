//! Implicit-shape generators: ellipsoid and a liver-like organ meshed on a regular or
//! body-centred grid, trimmed to the shape, boundary vertices snapped to the surface.
