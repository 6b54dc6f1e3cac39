// A quarter of a ring (a tunnel lining, x >= 0, z >= 0 about its axis along y), optionally in
// a quarter block of ground L wide and high, for the lining's checks against closed forms:
// the planes x = 0 and z = 0 are planes of symmetry. The x-z section is meshed with triangles
// (h in the ring, growing to h_far at a distance L / 2 from it) and extruded along y in
// layers (Ly thick in all).
// Physical names: volumes "ring" and, with L > 0, "ground"; surfaces "inner" (r = Ri),
// "outer" (r = Ro; without ground only), "x0" (x = 0), "z0" (z = 0), "sides" (y = 0 and
// y = Ly) and, with ground, "far_x" (x = L) and "far_z" (z = L).
SetFactory("OpenCASCADE");
DefineConstant[ Ri = {0.045, Name "Parameters/Ri"}, Ro = {0.05, Name "Parameters/Ro"},
                L = {0.0, Name "Parameters/L"}, Ly = {0.004, Name "Parameters/Ly"},
                h = {0.002, Name "Parameters/h"}, h_far = {0.02, Name "Parameters/h_far"} ];
eps = 1e-4 * (Ro + L);   // OpenCASCADE bounding boxes carry a tolerance
extent = Ro;
If (L > 0)
  extent = L;
EndIf
Disk(1) = {0, 0, 0, Ro};
Disk(2) = {0, 0, 0, Ri};
If (L > 0)
  Rectangle(3) = {0, 0, 0, L, L};
Else
  Rectangle(3) = {0, 0, 0, 1.01 * Ro, 1.01 * Ro};   // only its part inside Ro is kept
EndIf
BooleanFragments{ Surface{3}; Delete; }{ Surface{1, 2}; Delete; }
keep() = Surface In BoundingBox{-eps, -eps, -eps, extent + eps, extent + eps, eps};
keep() -= Surface In BoundingBox{-eps, -eps, -eps, Ri + eps, Ri + eps, eps};   // the opening
drop() = Surface{:};
drop() -= keep();
Recursive Delete { Surface{drop()}; }
section() = Surface{:};
Field[1] = MathEval;
Field[1].F = Sprintf("%g + (%g - %g) * Min(1, Max(0, Sqrt(x^2 + z^2) - %g) / %g)", h, h_far, h, Ro, L / 2 + 1e-9);  // after the rotation: the section in x-z
Background Field = 1;
Mesh.MeshSizeMin = 0.5 * h;
Rotate {{1, 0, 0}, {0, 0, 0}, Pi / 2} { Surface{section()}; }
Extrude {0, Ly, 0} { Surface{section()}; Layers{ Ceil(Ly / h) }; }
ring() = Volume In BoundingBox{-eps, -eps, -eps, Ro + eps, Ly + eps, Ro + eps};
Physical Volume("ring") = {ring()};
If (L > 0)
  ground() = Volume{:};
  ground() -= ring();
  Physical Volume("ground") = {ground()};
  xfar() = Surface In BoundingBox{L - eps, -eps, -eps, L + eps, Ly + eps, L + eps};
  zfar() = Surface In BoundingBox{-eps, -eps, L - eps, L + eps, Ly + eps, L + eps};
  Physical Surface("far_x") = {xfar()};
  Physical Surface("far_z") = {zfar()};
EndIf
Physical Surface("x0") = Surface In BoundingBox{-eps, -eps, -eps, eps, Ly + eps, extent + eps};
Physical Surface("z0") = Surface In BoundingBox{-eps, -eps, -eps, extent + eps, Ly + eps, eps};
sy0() = Surface In BoundingBox{-eps, -eps, -eps, extent + eps, eps, extent + eps};
sy1() = Surface In BoundingBox{-eps, Ly - eps, -eps, extent + eps, Ly + eps, extent + eps};
Physical Surface("sides") = {sy0(), sy1()};
inner() = Surface In BoundingBox{-eps, -eps, -eps, Ri + eps, Ly + eps, Ri + eps};
inner() -= {sy0(), sy1()};
inner() -= Surface In BoundingBox{-eps, -eps, -eps, eps, Ly + eps, Ri + eps};
inner() -= Surface In BoundingBox{-eps, -eps, -eps, Ri + eps, Ly + eps, eps};
Physical Surface("inner") = {inner()};
If (L == 0)
  outer() = Surface In BoundingBox{-eps, -eps, -eps, Ro + eps, Ly + eps, Ro + eps};
  outer() -= {sy0(), sy1(), inner()};
  outer() -= Surface In BoundingBox{-eps, -eps, -eps, eps, Ly + eps, Ro + eps};
  outer() -= Surface In BoundingBox{-eps, -eps, -eps, Ro + eps, Ly + eps, eps};
  Physical Surface("outer") = {outer()};
EndIf
