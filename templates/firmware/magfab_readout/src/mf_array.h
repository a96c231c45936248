/* An array's readout (a record of version 3, docs/bundle.md sections 3 and 4): every chip on the one bus, in
 * taxel order, each cycle one cycle frame in binary mode (every chip's counts, mf_frame_cycle_*) or a field line
 * per chip in text mode, no force (the host computes each taxel's from every taxel's field).
 *
 * Burst mode: every chip converts continuously and in parallel; each cycle reads them in turn (RM), the cycles
 * one conversion of the datasheet's table apart. Each chip is read on its own grid: the read margin after its
 * start, then one conversion on from each read scheduled on time, or from the read itself when it came late or
 * its chip's conversion did (the RM retry), so each read finds a conversion newer than the last and, while the
 * cycle fits in a conversion, none is skipped. When the frames or the bus take longer, the cycle is as long as
 * they take. Single mode: SM to every chip, one conversion's wait, then RM of each. Each chip converts the
 * temperature with its field, but a cycle reads it (two of the reply's nine bytes) from one chip in turn and from a
 * chip just started; the others' readings carry their latest temperature word.
 *
 * A chip that fails (NACK, ERROR bit, byte count, reset, timeout) gets its error frame, then is reset and
 * restarted at once as a single taxel's chip is; the others go on. A chip that does not start is lost: an error
 * frame every cycle (the fault of its last start) and a start attempt every MF_LOST_RETRY_US. A chip's first
 * frame after a start is flagged recovered. */
#ifndef MF_ARRAY_H
#define MF_ARRAY_H

#include "mf_app.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Start every chip of the record (flag their first frames recovered when recovered != 0). */
void mf_array_start(mf_app_t *a, uint8_t recovered);
/* One cycle: every chip read, one frame each, all with the same sequence number. */
void mf_array_poll(mf_app_t *a);

#ifdef __cplusplus
}
#endif

#endif
