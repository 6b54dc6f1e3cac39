// A strip footing on sand, a plane-strain slice (x, y, z from 0): a soil block W x Ly x H
// with a DEM zone w wide and d deep at the middle of its top, through the whole thickness
// Ly; the footing, B wide, is the middle of the zone's top. The x-z section is meshed with
// triangles whose size is h_near at the zone and grows linearly to h_far over the distance
// "grow"; the section is then extruded along y in layers about h_near thick, each prism split
// into tetrahedra (a free 3D mesh of this thin slice is either not reproducible, HXT, or has
// slivers, Delaunay: a smallest altitude of 1e-5 m, a 100x smaller FE step).
// Physical names: volumes "zone" (the DEM zone) and "soil" (the rest of the block); surfaces
// "footing" (z = H, |x - W/2| < B/2), "top" (the rest of z = H), "bottom" (z = 0), "sides_x"
// (x = 0 and x = W), "sides_y" (y = 0 and y = Ly: plane-strain rollers). The coupling
// interface (the zone's bottom and sides) is found by the solver from the cells.
DefineConstant[ W = {0.18, Name "Parameters/W"}, Ly = {0.012, Name "Parameters/Ly"},
                H = {0.06, Name "Parameters/H"}, w = {0.06, Name "Parameters/w"},
                d = {0.03, Name "Parameters/d"}, B = {0.015, Name "Parameters/B"},
                h_near = {0.004, Name "Parameters/h_near"}, h_far = {0.012, Name "Parameters/h_far"},
                grow = {0.03, Name "Parameters/grow"} ];
xa = (W - w) / 2; xb = (W + w) / 2; fa = (W - B) / 2; fb = (W + B) / 2;
// the soil's section, then the zone's: they share the points and lines of the trench
Point(1) = {0, 0, 0}; Point(2) = {W, 0, 0}; Point(3) = {W, 0, H}; Point(4) = {xb, 0, H};
Point(5) = {xb, 0, H - d}; Point(6) = {xa, 0, H - d}; Point(7) = {xa, 0, H}; Point(8) = {0, 0, H};
Point(9) = {fa, 0, H}; Point(10) = {fb, 0, H};
For k In {1:8}
  Line(k) = {k, k % 8 + 1};
EndFor
Line(9) = {4, 10}; Line(10) = {10, 9}; Line(11) = {9, 7};
Curve Loop(1) = {1:8};
Plane Surface(1) = {1};
Curve Loop(2) = {-6, -5, -4, 9, 10, 11};
Plane Surface(2) = {2};
soil[] = Extrude {0, Ly, 0} { Surface{1}; Layers{ Ceil(Ly / h_near) }; };
zone[] = Extrude {0, Ly, 0} { Surface{2}; Layers{ Ceil(Ly / h_near) }; };
eps = 1e-7 * (W + H);
Physical Volume("soil") = {soil[1]};
Physical Volume("zone") = {zone[1]};
Physical Surface("footing") = Surface In BoundingBox{fa-eps, -eps, H-eps, fb+eps, Ly+eps, H+eps};
top() = Surface In BoundingBox{-eps, -eps, H-eps, W+eps, Ly+eps, H+eps};
Physical Surface("top") = {top()};
Physical Surface("top") -= {Surface In BoundingBox{fa-eps, -eps, H-eps, fb+eps, Ly+eps, H+eps}};
Physical Surface("bottom") = Surface In BoundingBox{-eps, -eps, -eps, W+eps, Ly+eps, eps};
sx0() = Surface In BoundingBox{-eps, -eps, -eps, eps, Ly+eps, H+eps};
sx1() = Surface In BoundingBox{W-eps, -eps, -eps, W+eps, Ly+eps, H+eps};
Physical Surface("sides_x") = {sx0(), sx1()};
sy0() = Surface In BoundingBox{-eps, -eps, -eps, W+eps, eps, H+eps};
sy1() = Surface In BoundingBox{-eps, Ly-eps, -eps, W+eps, Ly+eps, H+eps};
Physical Surface("sides_y") = {sy0(), sy1()};
Field[1] = Distance;
Field[1].CurvesList = {4, 5, 6};
Field[1].NumPointsPerCurve = 40;
Field[2] = Threshold;
Field[2].InField = 1;
Field[2].SizeMin = h_near;
Field[2].SizeMax = h_far;
Field[2].DistMin = 0;
Field[2].DistMax = grow;
Background Field = 2;
Mesh.MeshSizeMin = 0.5 * h_near;  // below the case mesh_size: fe_domain.mesh keeps a source's own minimum
