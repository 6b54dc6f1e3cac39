// Backfill behind a retaining wall, a plane-strain slice (x, y, z from 0): the soil is
// L long (x), Ly thick (y), H high (z); the wall is its face x = 0 (a rigid surface in the
// case), the DEM zone the first a metres behind it (where the active wedge forms), the FE
// soil beyond. The x-z section is meshed with triangles of size h and extruded along y in
// layers h thick (a free 3D mesh of a thin slice has slivers). With h_far > h the FE soil's
// triangles grow from h at the zone's face to h_far a distance `grow` beyond it (a case's
// mesh_size must then be at least h_far: it is gmsh's largest size).
// Physical names: volumes "zone" (x < a) and "soil" (x > a); surfaces "wall" (x = 0),
// "far" (x = L), "base" (z = 0), "top" (z = H), "sides" (y = 0 and y = Ly).
// The coupling interface (x = a) is found by the solver from the cells: no group for it.
DefineConstant[ L = {0.14, Name "Parameters/L"}, Ly = {0.01, Name "Parameters/Ly"},
                H = {0.06, Name "Parameters/H"}, a = {0.05, Name "Parameters/a"},
                h = {0.005, Name "Parameters/h"} ];
DefineConstant[ h_far = {h, Name "Parameters/h_far"}, grow = {H, Name "Parameters/grow"} ];
Point(1) = {0, 0, 0, h}; Point(2) = {a, 0, 0, h}; Point(3) = {L, 0, 0, h};
Point(4) = {L, 0, H, h}; Point(5) = {a, 0, H, h}; Point(6) = {0, 0, H, h};
Line(1) = {1, 2}; Line(2) = {2, 5}; Line(3) = {5, 6}; Line(4) = {6, 1};
Line(5) = {2, 3}; Line(6) = {3, 4}; Line(7) = {4, 5};
Curve Loop(1) = {1, 2, 3, 4}; Plane Surface(1) = {1};
Curve Loop(2) = {5, 6, 7, -2}; Plane Surface(2) = {2};
If (h_far > h)
  Field[1] = Distance;
  Field[1].CurvesList = {2};
  Field[1].NumPointsPerCurve = 40;
  Field[2] = Threshold;
  Field[2].InField = 1;
  Field[2].SizeMin = h;
  Field[2].SizeMax = h_far;
  Field[2].DistMin = 0;
  Field[2].DistMax = grow;
  Background Field = 2;
  Mesh.MeshSizeMin = 0.5 * h;  // below the case mesh_size: fe_domain.mesh keeps a source's own minimum
EndIf
out1[] = Extrude {0, Ly, 0} { Surface{1}; Layers{ Ceil(Ly / h) }; };
out2[] = Extrude {0, Ly, 0} { Surface{2}; Layers{ Ceil(Ly / h) }; };
eps = 1e-7 * (L + H);
Physical Volume("zone") = {out1[1]};
Physical Volume("soil") = {out2[1]};
Physical Surface("wall") = Surface In BoundingBox{-eps, -eps, -eps, eps, Ly+eps, H+eps};
Physical Surface("far") = Surface In BoundingBox{L-eps, -eps, -eps, L+eps, Ly+eps, H+eps};
Physical Surface("base") = Surface In BoundingBox{-eps, -eps, -eps, L+eps, Ly+eps, eps};
Physical Surface("top") = Surface In BoundingBox{-eps, -eps, H-eps, L+eps, Ly+eps, H+eps};
sy0() = Surface In BoundingBox{-eps, -eps, -eps, L+eps, eps, H+eps};
sy1() = Surface In BoundingBox{-eps, Ly-eps, -eps, L+eps, Ly+eps, H+eps};
Physical Surface("sides") = {sy0(), sy1()};
