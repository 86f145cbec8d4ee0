// A race-free program that uses TBB the way the project does (a parallel_for whose results the
// caller reads after it returns, a parallel_pipeline handing heap objects from stage to stage, a
// task_group), for bench/tsan.sh: built with -fsanitize=thread, it must give no report. With
// Debian's libtbb12, which is not instrumented, it gives dozens: TSan cannot see the
// synchronisation inside the library (task hand-off, the end of a parallel_for, the pipeline's
// token passing), so every object handed between TBB threads looks racy, down to TBB's own inline
// code (blocked_range splitting, start_for, the pipeline's filter wrappers). A clean probe is the
// precondition of a meaningful TSan run of the project.
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_group.h>

#include <cstdio>
#include <vector>

struct Batch {
  std::vector<int> values;
};

int main() {
  long sum = 0;
  for (int round = 0; round < 20; ++round) {
    std::vector<int> v(1 << 14);
    tbb::parallel_for(size_t(0), v.size(), [&](size_t i) { v[i] = int(i); });
    for (int x : v) sum += x;
    int n = 0;
    tbb::parallel_pipeline(
        4,
        tbb::make_filter<void, Batch*>(tbb::filter_mode::serial_in_order,
                                       [&](tbb::flow_control& fc) -> Batch* {
                                         if (n == 50) {
                                           fc.stop();
                                           return nullptr;
                                         }
                                         ++n;
                                         return new Batch;
                                       }) &
            tbb::make_filter<Batch*, Batch*>(tbb::filter_mode::parallel,
                                             [](Batch* b) {
                                               b->values.assign(100, 1);
                                               return b;
                                             }) &
            tbb::make_filter<Batch*, void>(tbb::filter_mode::serial_in_order, [&](Batch* b) {
              sum += b->values[3];
              delete b;
            }));
    int t = 0;
    tbb::task_group g;
    g.run([&] { t = 5; });
    g.wait();
    sum += t;
  }
  std::printf("%ld\n", sum);
  return 0;
}
