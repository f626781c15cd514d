#pragma once
// The LCM side of the input: a thread that runs lcm_handle, decodes sample_t
// and sample2_t packets (samples channel), sample_batch_t and sample_batch2_t
// packets (batches channel), for the model's number of inputs, and pushes the
// samples into the input ring. It never blocks on the estimation loop: a full
// ring drops (and counts) samples.
#include <lcm/lcm.h>

#include <atomic>
#include <thread>
#include <vector>

#include "counters.hpp"
#include "loss_counter.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/io/messages.hpp"
#include "spsc_ring.hpp"

namespace modalwatch::daemon_detail {

class Subscriber {
 public:
  // `lcm` and `output` must outlive the subscriber; the settings are copied
  // (a reload rewrites the daemon's config while this thread runs).
  Subscriber(lcm_t* lcm, const Config& config, SpscRing<StampedSample>& output, SubscriberCounters& counters);
  ~Subscriber() { stop(); }
  Subscriber(const Subscriber&) = delete;
  Subscriber& operator=(const Subscriber&) = delete;

  void start();  // subscribes and starts the thread; throws std::runtime_error when LCM refuses
  void stop();   // joins the thread and unsubscribes; idempotent

 private:
  static void on_sample_packet(const lcm_recv_buf_t* rbuf, const char* channel, void* user);
  static void on_batch_packet(const lcm_recv_buf_t* rbuf, const char* channel, void* user);
  void on_packet(const lcm_recv_buf_t* rbuf, bool batch) noexcept;
  void run();

  lcm_t* lcm_;
  SpscRing<StampedSample>& output_;
  SubscriberCounters& counters_;
  const LcmSettings channels_;
  const bool closed_loop_;
  const int inputs_;  // the model's (a packet of another count is a decode error)
  const int realtime_priority_;
  std::vector<StampedSample> decoded_;  // one packet's samples
  LossCounter loss_;                    // this thread's only
  lcm_subscription_t* sub_samples_ = nullptr;
  lcm_subscription_t* sub_batches_ = nullptr;
  std::thread thread_;
  std::atomic<bool> stop_{false};
};

}  // namespace modalwatch::daemon_detail
