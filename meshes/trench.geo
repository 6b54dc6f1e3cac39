// Soil block W x Ly x H (x, y, z from 0) with a trench-shaped cavity w wide and d deep at
// the middle of its top, through the whole thickness Ly (a plane-strain slice): the cavity
// holds a DEM zone (docs/design.md §7); its bottom and two side faces are the coupling
// interface. The element size is h_near at the cavity and grows linearly to
// h_far over the distance "grow" (a case passes its mesh_size as h_far).
// Physical names: volume "soil"; faces "zone" (the cavity's bottom and sides), "top"
// (the free surface beside the cavity), "bottom" (z = 0), "sides_x" (x = 0 and x = W),
// "sides_y" (y = 0 and y = Ly: plane-strain rollers).
SetFactory("OpenCASCADE");
DefineConstant[ W = {0.18, Name "Parameters/W"}, Ly = {0.012, Name "Parameters/Ly"},
                H = {0.06, Name "Parameters/H"}, w = {0.06, Name "Parameters/w"},
                d = {0.03, Name "Parameters/d"}, h_near = {0.004, Name "Parameters/h_near"},
                h_far = {0.012, Name "Parameters/h_far"}, grow = {0.03, Name "Parameters/grow"} ];
xa = (W - w) / 2; xb = (W + w) / 2;
Box(1) = {0, 0, 0, W, Ly, H};
Box(2) = {xa, 0, H - d, w, Ly, d};
BooleanDifference{ Volume{1}; Delete; }{ Volume{2}; Delete; }
eps = 1e-7;
Physical Volume("soil") = {1};
zone() = Surface In BoundingBox{xa-eps, -eps, H-d-eps, xb+eps, Ly+eps, H+eps};
Physical Surface("zone") = {zone()};
Physical Surface("top") = Surface In BoundingBox{-eps, -eps, H-eps, W+eps, Ly+eps, H+eps};
Physical Surface("bottom") = Surface In BoundingBox{-eps, -eps, -eps, W+eps, Ly+eps, eps};
sx0() = Surface In BoundingBox{-eps, -eps, -eps, eps, Ly+eps, H+eps};
sx1() = Surface In BoundingBox{W-eps, -eps, -eps, W+eps, Ly+eps, H+eps};
Physical Surface("sides_x") = {sx0(), sx1()};
sy0() = Surface In BoundingBox{-eps, -eps, -eps, W+eps, eps, H+eps};
sy1() = Surface In BoundingBox{-eps, Ly-eps, -eps, W+eps, Ly+eps, H+eps};
Physical Surface("sides_y") = {sy0(), sy1()};
Field[1] = Distance;
Field[1].SurfacesList = {zone()};
Field[1].NumPointsPerCurve = 20;
Field[2] = Threshold;
Field[2].InField = 1;
Field[2].SizeMin = h_near;
Field[2].SizeMax = h_far;
Field[2].DistMin = 0;
Field[2].DistMax = grow;
Background Field = 2;
Mesh.MeshSizeMin = 0.5 * h_near;  // below the case mesh_size: fe_domain.mesh keeps a source's own minimum
