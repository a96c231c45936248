/* An array's readout (a record of version 3, docs/bundle.md sections 3 and 4): every chip on the one bus, in
 * taxel order, one field frame per chip per cycle (mf_frame_field), no force (the host computes each taxel's from
 * every taxel's field).
 *
 * Burst mode: every chip converts continuously and in parallel; each cycle reads them in turn (RM), the cycles
 * one conversion of the datasheet's table plus the read margin apart, and no chip read sooner than that after
 * its start or its last read, so each read finds a conversion newer than the last whatever the chips' phases (a
 * chip's start makes its phase; about one conversion in 1 / margin is never read). When the frames or the bus
 * take longer, the cycle is as long as they take. Single mode: SM to every chip, one conversion's wait, then
 * RM of each.
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
