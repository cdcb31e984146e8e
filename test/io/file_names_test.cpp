// A file name's extension as the mesh, surface and vessel readers and the tools take it.
#include <gtest/gtest.h>

#include "liver_sim/io/file_names.h"

namespace liver_sim {
namespace {

// Mutations killed: the folder check dropped, the case kept, the dot kept.
TEST(FileNames, TheExtensionIsTheNamesLowerCaseAndNotAFoldersDot) {
  EXPECT_EQ(file_extension("trees/portal.VTK"), "vtk");
  EXPECT_EQ(file_extension("/data/case.1/portal"), "");
  EXPECT_EQ(file_extension("portal"), "");
  EXPECT_EQ(file_extension("portal."), "");
  EXPECT_EQ(file_extension("a.b/portal.yml"), "yml");
}

}  // namespace
}  // namespace liver_sim
