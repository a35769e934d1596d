// Standard brick face 0.25 m x 0.06 m (lower-left corner at the origin) with named faces.
// fem_blocks meshes it with `geometry = "file"`; structured quads (transfinite + recombine), about lc = 0.01 m.
lx = 0.25;  ly = 0.06;  lc = 0.01;
Point(1) = {0, 0, 0, lc};
Point(2) = {lx, 0, 0, lc};
Point(3) = {lx, ly, 0, lc};
Point(4) = {0, ly, 0, lc};
Line(1) = {1, 2};
Line(2) = {2, 3};
Line(3) = {3, 4};
Line(4) = {4, 1};
Curve Loop(1) = {1, 2, 3, 4};
Plane Surface(1) = {1};
Transfinite Curve {1, 3} = Round(lx / lc) + 1;
Transfinite Curve {2, 4} = Round(ly / lc) + 1;
Transfinite Surface {1} = {1, 2, 3, 4};
Recombine Surface {1};
Physical Curve("bottom") = {1};
Physical Curve("right") = {2};
Physical Curve("top") = {3};
Physical Curve("left") = {4};
Physical Surface("brick") = {1};
