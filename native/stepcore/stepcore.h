// The step core's C ABI (stepcore.cc): the per-step work both robots run. The Python robot
// loads build/libstepcore.so with ctypes (node/stepcore.py declares the same signatures); the
// C++ robot (native/robot) links stepcore.cc in. One laser, one map update, one planner.
// bodylink.cc, in the library only, is the world's: its body links' per-step input and output.
// Arrays are C-contiguous; booleans are one byte, 0 or 1.
#pragma once

#include <cstdint>

extern "C" {

int sc_version(void);
int sc_window_marks(const float* dx, const float* dy, const uint8_t* mark, int n_rays,
                    int n_samples, int w, float fx, float fy, int roff, int coff,
                    const int32_t* idx, uint8_t* free_out, int64_t* occ_out);
void sc_mark_table(const uint8_t* sure, int w, const float* odx, const float* ody, int n_open,
                   float fx, float fy, int roff, int coff, uint8_t* dst, int64_t stride,
                   int or_into);
int64_t sc_world_cast(int n, const double* xy, const uint8_t* want, double map_cell,
                      double laser_cell, int bias, int pad, int w, const float* dx,
                      const float* dy, const uint8_t* mark, int n_rays, int n_samples,
                      double step, int tabled, int frac, int buckets,
                      const uint8_t* const* sures, const float* const* odxs,
                      const float* const* odys, const int32_t* n_opens, const uint8_t* occ,
                      uint8_t* seen, const uint8_t* free_pad, int64_t ph, int64_t pw,
                      const uint8_t* open_space, const int32_t* skip, int64_t mh, int64_t mw,
                      float* ranges_out, int8_t* hit_out, int32_t* idx_tmp);
int64_t sc_world_cast_moved(const double* xyt, const uint8_t* live, int8_t* has_out,
                            int32_t* fallbacks_out, int n, double* xy, uint8_t* want,
                            double map_cell, double laser_cell, int bias, int pad, int w,
                            const float* dx, const float* dy, const uint8_t* mark, int n_rays,
                            int n_samples, double step, int tabled, int frac, int buckets,
                            const uint8_t* const* sures, const float* const* odxs,
                            const float* const* odys, const int32_t* n_opens,
                            const uint8_t* occ, uint8_t* seen, const uint8_t* free_pad,
                            int64_t ph, int64_t pw, const uint8_t* open_space,
                            const int32_t* skip, int64_t mh, int64_t mw, float* ranges_out,
                            int8_t* hit_out, int32_t* idx_tmp);
void sc_scan_into(const float* dx, const float* dy, const uint8_t* mark, int n_rays,
                  int n_samples, float step, int w, float fx, float fy, int roff, int coff,
                  const float* ranges, float* lp, uint8_t* own, int64_t stride, int64_t r0,
                  int64_t c0, float l_free, float l_occ, float l_max, uint8_t* free_tmp,
                  int64_t* occ_tmp, const uint8_t* sure, const float* odx, const float* ody,
                  int n_open);
void sc_classify(const float* l, int h, int w, int64_t stride, float threshold, uint8_t* out);
int64_t sc_merge_ternary(float* l, int64_t stride, const uint8_t* t, int h, int w,
                         float threshold, float merged);
int sc_plan(const uint8_t* t, int th, int tw, int factor, int inflate, double px, double py,
            double plan_cell, const double* goals, int n_goals, double radius, int fallback_ok,
            int* status_out, int* path_out, int max_n);

// The world's side of the body links (bodylink.cc): a step's commands in, its frames out.
int64_t sc_body_take(int n, const int32_t* fds, int32_t* taken, int64_t* step_out,
                     uint8_t* go_out, double* xy_out, uint8_t* hung, uint8_t* others,
                     int64_t others_cap, int32_t* counts_out);
int sc_body_frames(int n, const int32_t* fds, const uint8_t* live, int64_t step,
                   const double* xyt, double sent, const float* ranges, const int8_t* has_ranges,
                   int n_rays);

}  // extern "C"
