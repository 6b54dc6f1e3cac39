// Slender bar along x: length L, square cross-section W x W.
// Physical names: volume "solid"; faces "left" (x=0), "right" (x=L),
// "side_y" (y=0 and y=W), "side_z" (z=0 and z=W).
// Mesh size: set Mesh.MeshSizeMax from the loader (fe_domain.mesh.load_geo).
SetFactory("OpenCASCADE");
DefineConstant[ L = {1.0, Name "Parameters/L"}, W = {0.1, Name "Parameters/W"} ];
Box(1) = {0, 0, 0, L, W, W};
eps = 1e-6;
Physical Volume("solid") = {1};
Physical Surface("left") = Surface In BoundingBox{-eps, -eps, -eps, eps, W+eps, W+eps};
Physical Surface("right") = Surface In BoundingBox{L-eps, -eps, -eps, L+eps, W+eps, W+eps};
sy0() = Surface In BoundingBox{-eps, -eps, -eps, L+eps, eps, W+eps};
sy1() = Surface In BoundingBox{-eps, W-eps, -eps, L+eps, W+eps, W+eps};
sz0() = Surface In BoundingBox{-eps, -eps, -eps, L+eps, W+eps, eps};
sz1() = Surface In BoundingBox{-eps, -eps, W-eps, L+eps, W+eps, W+eps};
Physical Surface("side_y") = {sy0(), sy1()};
Physical Surface("side_z") = {sz0(), sz1()};
