#pragma once
/// @file serial_queue.hpp
/// Work that must run on one thread (an OpenGL context is current on one
/// thread only), handed to it by others, which wait for the result.

#include <condition_variable>
#include <deque>
#include <exception>
#include <functional>
#include <mutex>
#include <stdexcept>

namespace tigerlod {

class SerialQueue {
  public:
    /// From any thread: runs `work` on the serving thread and waits for it;
    /// its exception is rethrown here. Throws std::logic_error after close().
    void run(const std::function<void()>& work)
    {
        // The job lives in this frame: the serving thread drops every
        // reference to the exception before `done` is set under the mutex,
        // so the exception is freed here, after the hand-over.
        Job job{&work, nullptr, false};
        {
            std::unique_lock lock(m_mutex);
            if (m_closed) {
                throw std::logic_error("SerialQueue::run after close");
            }
            m_jobs.push_back(&job);
            m_cv.notify_all();
            m_cv.wait(lock, [&] { return job.done; });
        }
        if (job.error) {
            std::rethrow_exception(job.error);
        }
    }

    /// On the serving thread: runs the jobs in the order they came, until
    /// close() has been called and none is left.
    void serve()
    {
        for (;;) {
            Job* job = nullptr;
            {
                std::unique_lock lock(m_mutex);
                m_cv.wait(lock, [&] { return m_closed || !m_jobs.empty(); });
                if (m_jobs.empty()) {
                    return;
                }
                job = m_jobs.front();
                m_jobs.pop_front();
            }
            std::exception_ptr error;
            try {
                (*job->work)();
            } catch (...) {
                error = std::current_exception();
            }
            std::lock_guard lock(m_mutex);
            job->error = std::move(error);
            job->done = true;
            m_cv.notify_all();
        }
    }

    /// No more jobs will come: serve() returns once the queue is empty.
    void close()
    {
        std::lock_guard lock(m_mutex);
        m_closed = true;
        m_cv.notify_all();
    }

  private:
    struct Job {
        const std::function<void()>* work;
        std::exception_ptr error;
        bool done;
    };
    std::mutex m_mutex;
    std::condition_variable m_cv; // jobs queued, jobs done, closed
    std::deque<Job*> m_jobs;
    bool m_closed = false;
}; // class SerialQueue

} // namespace tigerlod
