/* Frames through the C ABI (protocol v4): the terminal-descent example flight software,
 * plus the optional oils_fsw_frame, which checks every frame it is handed against its
 * announcement: the length, the test card's frame counter in its first four pixels, and
 * the XXH3-64 hash (libxxhash's XXH3_64bits, declared here so that no xxhash header is
 * needed; link with -l:libxxhash.so.0). The pixels are read in place, in the frame
 * service's shared memory: nothing is copied.
 *
 *   cc -std=c11 -O2 -shared -fPIC -I shared/include onboard-stub/examples/c/frames.c \
 *      -o libframes.so -lm -l:libxxhash.so.0
 *   oils run --no-stub --scenario S --run-id ID   (S with [sensors.test_card] enabled = true)
 *   oils stub --run-id ID --fsw c:./libframes.so
 *
 * At the end it prints "frames: N checked" on standard error. A frame that does not
 * match stops the run (status 7).
 */
/* The example's fini, renamed, so this file's can report before calling it. */
#define oils_fsw_fini terminal_descent_fini
#include "terminal_descent.c"
#undef oils_fsw_fini

unsigned long long XXH3_64bits(const void *data, size_t len);

static unsigned long long frames_checked;

int32_t oils_fsw_frame(void *ctx, const oils_frame_announcement *ann,
                       const uint8_t *pixels, size_t len) {
  (void)ctx;
  if (len != ann->bytes || XXH3_64bits(pixels, len) != ann->hash) {
    fprintf(stderr, "frames: frame %llu of device %u does not match its announcement\n",
            (unsigned long long)ann->seq, ann->device);
    return 7;
  }
  if (ann->device == OILS_FRAME_DEVICE_TEST_CARD && len >= 8) {
    uint64_t seq = 0;
    for (int w = 0; w < 4; w++) {
      seq |= (uint64_t)(pixels[2 * w] | (pixels[2 * w + 1] << 8)) << (16 * w);
    }
    if (seq != ann->seq) {
      fprintf(stderr, "frames: the test card says frame %llu, announced %llu\n",
              (unsigned long long)seq, (unsigned long long)ann->seq);
      return 7;
    }
  }
  frames_checked++;
  return OILS_FSW_STATUS_OK;
}

void oils_fsw_fini(void *ctx) {
  fprintf(stderr, "frames: %llu checked\n", frames_checked);
  terminal_descent_fini(ctx);
}
