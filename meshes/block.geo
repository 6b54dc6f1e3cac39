// Rectangular block Lx x Ly x Lz with one physical group per face.
// Physical names: volume "solid"; faces "x0", "x1", "y0", "y1", "bottom" (z=0), "top" (z=Lz).
SetFactory("OpenCASCADE");
DefineConstant[ Lx = {1.0, Name "Parameters/Lx"}, Ly = {1.0, Name "Parameters/Ly"},
                Lz = {1.0, Name "Parameters/Lz"} ];
Box(1) = {0, 0, 0, Lx, Ly, Lz};
eps = 1e-6;
Physical Volume("solid") = {1};
Physical Surface("x0") = Surface In BoundingBox{-eps, -eps, -eps, eps, Ly+eps, Lz+eps};
Physical Surface("x1") = Surface In BoundingBox{Lx-eps, -eps, -eps, Lx+eps, Ly+eps, Lz+eps};
Physical Surface("y0") = Surface In BoundingBox{-eps, -eps, -eps, Lx+eps, eps, Lz+eps};
Physical Surface("y1") = Surface In BoundingBox{-eps, Ly-eps, -eps, Lx+eps, Ly+eps, Lz+eps};
Physical Surface("bottom") = Surface In BoundingBox{-eps, -eps, -eps, Lx+eps, Ly+eps, eps};
Physical Surface("top") = Surface In BoundingBox{-eps, -eps, Lz-eps, Lx+eps, Ly+eps, Lz+eps};
