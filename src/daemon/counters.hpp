#pragma once
// The daemon's counters, grouped by the thread that writes them. Each counter
// has one writer, so bump() is a relaxed load and store rather than a
// read-modify-write; any thread may read. DaemonCounters::samples_dropped is
// the sum of the subscriber's and the loop's drops, each counted by its owner.
#include <atomic>
#include <cstdint>

#include "modalwatch/daemon/daemon.hpp"

namespace modalwatch::daemon_detail {

using Counter = std::atomic<std::uint64_t>;

inline void bump(Counter& c, std::uint64_t n = 1) noexcept {
  c.store(c.load(std::memory_order_relaxed) + n, std::memory_order_relaxed);
}

inline std::uint64_t read(const Counter& c) noexcept { return c.load(std::memory_order_relaxed); }

struct SubscriberCounters {
  Counter samples_received{0}, ring_full{0}, decode_errors{0}, samples_lost{0};
};

struct LoopCounters {
  Counter samples_nonfinite{0}, samples_duplicate{0}, samples_out_of_order{0}, samples_processed{0}, gaps{0}, resets{0},
      change_boosts{0}, mode_restores{0}, overruns{0}, sender_restarts{0}, samples_held{0}, held_dropped{0}, snapshots{0},
      snapshots_dropped{0}, flag_changes{0};
};

struct PublisherCounters {
  Counter estimates_published{0}, fault_status_published{0}, heartbeats_published{0};
};

// Written by the checkpointer thread, and by the control thread after stop().
struct CheckpointCounters {
  Counter written{0}, failures{0};
};

struct Counters {
  SubscriberCounters subscriber;
  LoopCounters loop;
  PublisherCounters publisher;
  CheckpointCounters checkpoints;

  DaemonCounters load() const noexcept {
    DaemonCounters c;
    c.samples_received = read(subscriber.samples_received);
    c.samples_dropped = read(subscriber.ring_full) + read(loop.held_dropped);
    c.decode_errors = read(subscriber.decode_errors);
    c.samples_lost = read(subscriber.samples_lost);
    c.samples_nonfinite = read(loop.samples_nonfinite);
    c.samples_duplicate = read(loop.samples_duplicate);
    c.samples_out_of_order = read(loop.samples_out_of_order);
    c.sender_restarts = read(loop.sender_restarts);
    c.samples_processed = read(loop.samples_processed);
    c.gaps = read(loop.gaps);
    c.resets = read(loop.resets);
    c.change_boosts = read(loop.change_boosts);
    c.mode_restores = read(loop.mode_restores);
    c.overruns = read(loop.overruns);
    c.samples_held = read(loop.samples_held);
    c.held_dropped = read(loop.held_dropped);
    c.snapshots = read(loop.snapshots);
    c.snapshots_dropped = read(loop.snapshots_dropped);
    c.estimates_published = read(publisher.estimates_published);
    c.fault_status_published = read(publisher.fault_status_published);
    c.heartbeats_published = read(publisher.heartbeats_published);
    c.flag_changes = read(loop.flag_changes);
    c.checkpoints_written = read(checkpoints.written);
    c.checkpoint_failures = read(checkpoints.failures);
    return c;
  }
};

}  // namespace modalwatch::daemon_detail
