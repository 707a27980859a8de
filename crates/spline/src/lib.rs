//! volmorph-spline: Knot vectors, B-spline/NURBS/Bernstein bases, curves, surfaces and trivariate volumes, knot insertion, Bezier extraction, Greville interpolation. No I/O.
