# Test properties set when ctest reads the tests (tests/CMakeLists.txt includes this file after the
# files of gtest_discover_tests, whose test lists, <target>_TESTS, are set by then).
#
# COST: ctest -j starts the tests of highest cost first. On a fresh build directory ctest has no
# timings of its own (Testing/Temporary/CTestCostData.txt), so without these the slowest tests
# start wherever their executable is declared and, on 2 cores, can run alone at the end. The
# figures are seconds of a Release run (docs/hardening.md, "Measured"); only the order matters.

set(_mt_costs
  RealScans.ScanDerivedMeshesKeepThePromises 377
  RealScans.EveryMtgenPathologyKeepsThePromises 315
  RealScans.QuadricSimplifierKeepsThePromises 277
  Faults.EveryWriteFsyncAndRenameOfABuildLeavesNothingOrTheWholeFileAndResumes 173
  TexturedScan.DragonBuildsCrackFreeAndDrawsItsTextureAtOnePixel 168
  StoreSafety.TwoHealsAtOnceGiveOneGoodResultAndOneRefusal 168
  PatchStore.SameStoreBytesWhateverTheCapOrThePath 64
  RenderPolicies.AModelBehindAWallWithAWindowIsNeitherDrawnNorLoadedWhereHiddenAndLooksTheSame 43
  MtRender.NoCracksInAnyCut 39
  BoundedConformity.SameReferenceAndCountsAsInMemoryOnClosedHoledMultiComponentAndNonManifoldMeshes 39
  RenderPolicies.CullingNeverChangesTheImageOfAHoledScanAndConesStillCullAClosedOne 38
  TexturedBuild.RendersTheTextureCloseToTheFullResolution 38
  PatchStore.ChunkedJoinThroughWindowsAndBucketsGivesTheResidentBytes 37
  Georeferenced.CentimetreGridAtUtmCoordinatesKeepsEveryTriangleInEveryFormat 37
  StreamedWeld.MtextractWritesTheSameBytesWithinASmallMemory 36
  ColourBuild.RendersTheColoursCloseToTheFullResolution 35
  StoreSafety.SmoothReclaimsOldBlocksAndPrintsOneLinePerIteration 34
  TextureBuild.EveryLevelShowsTheInputsColours 30
  RenderPolicies.AGeoreferencedModelRendersLikeTheSameModelAtTheOrigin 24
  RenderPolicies.PlotWritesOnePngPerSeries 24
  ExitCodes.RandomByteFlipsAreReportedWithThePatchOrSection 24
  BuildSafety.ResumeFingerprintCoversEveryByteAndSaysTheTimeReadably 23
  Mtbuild.CutsAreCrackFreeOnClosedHoledMultiComponentAndNonManifoldMeshes 22
  MtbuildWindow.TheLevelLoopHonoursItsByteBudgetAndKeepsTheBytes 20
  Mtcluster.ADeadRankStopsTheJobNamingRankAndLevelAndResumeFinishes 20
  RenderPolicies.TheHeapsAreReKeyedWithinTheDeadlineAndTheCutStillConverges 20
  MtstoreCli.MillionTriangleScanRoundTripsExactly 19
)

set(_mt_tests "")
get_cmake_property(_mt_vars VARIABLES)
foreach(_v IN LISTS _mt_vars)
  if(_v MATCHES "^test_[a-z_0-9]+_TESTS$")
    list(APPEND _mt_tests ${${_v}})
  endif()
endforeach()

list(LENGTH _mt_costs _n)
set(_i 0)
while(_i LESS _n)
  list(GET _mt_costs ${_i} _name)
  math(EXPR _j "${_i} + 1")
  list(GET _mt_costs ${_j} _cost)
  list(FIND _mt_tests "${_name}" _k)  # (ctest reads this file with the old policies: no IN_LIST)
  if(_k GREATER -1)
    set_tests_properties(${_name} PROPERTIES COST ${_cost})
  endif()
  math(EXPR _i "${_i} + 2")
endwhile()
