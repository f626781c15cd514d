#include "subscriber.hpp"

#include <lcm/lcm.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <limits>
#include <stdexcept>

#include "realtime.hpp"

namespace modalwatch::daemon_detail {
namespace {

// Largest batch decoded (36 + 24 * 8192 bytes, about 200 kB, for one input).
constexpr int kMaxBatch = 8192;

}  // namespace

Subscriber::Subscriber(lcm_t* lcm, const Config& config, SpscRing<StampedSample>& output, SubscriberCounters& counters)
    : lcm_(lcm),
      output_(output),
      counters_(counters),
      channels_(config.lcm),
      closed_loop_(config.closed_loop),
      inputs_(config.model.n_inputs()),
      realtime_priority_(config.daemon.realtime_priority),
      decoded_(kMaxBatch) {}

void Subscriber::start() {
  if (thread_.joinable()) return;
  stop_.store(false);
  {
    const ScopedRealtime rt(realtime_priority_);  // for LCM's receive thread, started here
    sub_samples_ = lcm_subscribe(lcm_, channels_.samples_channel.c_str(), &Subscriber::on_sample_packet, this);
    sub_batches_ = lcm_subscribe(lcm_, channels_.batches_channel.c_str(), &Subscriber::on_batch_packet, this);
  }
  if (!sub_samples_ || !sub_batches_) throw std::runtime_error("lcm_subscribe failed");
  // LCM's default of 30 queued packets per subscription drops bursts before we see them.
  lcm_subscription_set_queue_capacity(sub_samples_, 100000);
  lcm_subscription_set_queue_capacity(sub_batches_, 10000);
  thread_ = std::thread([this] { run(); });
}

void Subscriber::stop() {
  if (thread_.joinable()) {
    stop_.store(true, std::memory_order_release);
    thread_.join();
  }
  if (sub_samples_) lcm_unsubscribe(lcm_, sub_samples_);
  if (sub_batches_) lcm_unsubscribe(lcm_, sub_batches_);
  sub_samples_ = sub_batches_ = nullptr;
}

void Subscriber::on_sample_packet(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  static_cast<Subscriber*>(user)->on_packet(rbuf, false);
}

void Subscriber::on_batch_packet(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  static_cast<Subscriber*>(user)->on_packet(rbuf, true);
}

void Subscriber::on_packet(const lcm_recv_buf_t* rbuf, bool batch) noexcept {
  int n = 0;
  const int size = rbuf->data_size > static_cast<std::uint32_t>(std::numeric_limits<int>::max())
                       ? std::numeric_limits<int>::max()
                       : static_cast<int>(rbuf->data_size);
  const DecodeResult r = batch ? decode_batch(rbuf->data, size, closed_loop_, decoded_.data(), kMaxBatch, n, inputs_)
                               : decode_sample(rbuf->data, size, closed_loop_, decoded_.data(), kMaxBatch, n, inputs_);
  if (r != DecodeResult::ok) {
    bump(counters_.decode_errors);
    return;
  }
  bump(counters_.samples_received, static_cast<std::uint64_t>(n));
  std::uint64_t dropped = 0, lost = 0;
  for (int i = 0; i < n; ++i) {
    const StampedSample& s = decoded_[static_cast<std::size_t>(i)];
    lost += loss_.observe(s.seq, s.utime);
    if (!output_.try_push(s)) ++dropped;
  }
  if (dropped) bump(counters_.ring_full, dropped);
  if (lost) bump(counters_.samples_lost, lost);
}

void Subscriber::run() {
  name_this_thread("mw-subscribe");
  make_realtime(realtime_priority_);
  while (!stop_.load(std::memory_order_acquire)) {
    const int handled = lcm_handle_timeout(lcm_, 20);
    if (handled == 0) {
      // Idle: what has not arrived by now is lost, not late.
      if (const std::uint64_t lost = loss_.flush()) bump(counters_.samples_lost, lost);
    } else if (handled < 0) {
      spdlog::error("lcm_handle failed; retrying in 100 ms");
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  }
  if (const std::uint64_t lost = loss_.flush()) bump(counters_.samples_lost, lost);
}

}  // namespace modalwatch::daemon_detail
