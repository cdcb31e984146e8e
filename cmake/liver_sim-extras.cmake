# For packages that build against liver_sim (catkin_package's CFG_EXTRAS): code that includes its
# headers lays out Eigen's fixed-size objects as its libraries do (aligned as in code built
# without AVX, CMakeLists.txt), so that an object passed across has one layout on both sides.
add_compile_definitions(EIGEN_MAX_ALIGN_BYTES=16)
